"""Coded structured light (Fusiello ch. 13.2): patterns, decoding, the projector's response, triangulation.

Modules: ``patterns`` (what is projected), ``decode`` (capture stack -> projector coordinates, with
``binary`` and ``phase`` for the code families, ``debruijn`` for single-shot colour stripes, ``result``
for :class:`DecodeResult`), ``response`` (gamma fit and phase correction), ``triangulate`` (camera pixel +
projector coordinate -> 3D point), ``uncertainty`` (camera noise model, decoded-coordinate std, and its
propagation to a per-point sigma along the camera ray); ``codecs/`` holds other tools' fringe codecs (SLStudio's
micro and modulated phase shifting, OpenCV's FTP, PSP and FAPS).
"""

from rangekit._runtime.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
