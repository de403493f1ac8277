"""Fringe codecs of other structured-light tools, projected and decoded by rangekit (issue 35).

Each method's frames are the tool's own, value for value (its formula, its float precision, its rounding),
so the simulator renders what the tool projects and a layout preset can decode the tool's folder as it lies
on disk. Methods (see :mod:`rangekit.coded.codecs.fringes` for every frame's formula and source):

``micro``
    Micro phase shifting (Gupta & Nayar, CVPR 2012) as SLStudio's ``CodecPhaseShiftMicro``: ten periods in
    a narrow band; decoded by :mod:`rangekit.coded.codecs.micro`.
``modulated``
    SLStudio's ``CodecPhaseShiftModulated``: a 3-step fringe modulated by a perpendicular 3-step carrier
    (direct light isolated), with a one-period cue; decoded by :mod:`rangekit.coded.codecs.modulated`.
``ftp``, ``psp``, ``faps``
    OpenCV contrib's ``SinusoidalPattern`` (Fourier-transform profilometry, phase-shifting profilometry,
    Fourier-assisted phase shifting), plus a one-period cue that makes the column absolute; decoded by
    :mod:`rangekit.coded.codecs.sinusoidal` (the Fourier analysis in :mod:`rangekit.coded.codecs.ftp`).

:func:`rangekit.coded.decode.decode` sends these methods to :func:`rangekit.coded.codecs.decoders.decode_fringes`.
The two-frequency (SLStudio ``CodecPhaseShift2x3``, ``NStep``) and single-period (``CodecPhaseShift3``,
``3FastWrap``, ``4``) codecs are rangekit's ``phase`` method (its option ``rounding: "down"`` gives SLStudio's
truncated frames); docs/coded-light.md lists them.

This package's ``__init__`` imports nothing: :mod:`rangekit.coded.patterns` imports ``fringes`` from here.
"""
