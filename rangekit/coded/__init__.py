"""Coded structured light (Fusiello ch. 13.2): patterns, decoding, the projector's response, triangulation.

Modules: ``patterns`` (what is projected), ``decode`` (capture stack -> projector coordinates, with
``binary`` and ``phase`` for the code families, ``debruijn`` for single-shot colour stripes, ``result``
for :class:`DecodeResult`), ``response`` (gamma fit and phase correction), ``triangulate`` (camera pixel +
projector coordinate -> 3D point), ``uncertainty`` (camera noise model, decoded-coordinate std, and its
propagation to a per-point sigma along the camera ray); ``codecs/`` holds other tools' fringe codecs (SLStudio's
micro and modulated phase shifting, OpenCV's FTP, PSP and FAPS).
"""

from rangekit.coded.debruijn import decode_debruijn
from rangekit.coded.decode import decode
from rangekit.coded.patterns import (DEBRUIJN_PALETTE, PATTERN_METHODS, PatternSpec, de_bruijn,
                                     debruijn_stripe_colours, gray_decode, gray_encode, make_pattern_spec,
                                     n_bits_for)
from rangekit.coded.phase import phase_from_steps
from rangekit.coded.response import PhaseCorrection, ResponseFit, fit_response, phase_correction
from rangekit.coded.result import DecodeResult
from rangekit.coded.triangulate import (TriangulationResult, discontinuity_mask, range_normals, triangulate,
                                        triangulate_ray_plane, triangulate_ray_ray)
from rangekit.coded.uncertainty import (GRAY_CODE_STD, NoiseModel, along_ray_jacobian, fit_noise_model,
                                        phase_coordinate_std, point_sigma)

__all__ = [
    "PatternSpec", "PATTERN_METHODS", "make_pattern_spec", "gray_encode", "gray_decode", "n_bits_for",
    "de_bruijn", "DEBRUIJN_PALETTE", "debruijn_stripe_colours",
    "DecodeResult", "decode", "decode_debruijn", "phase_from_steps",
    "ResponseFit", "PhaseCorrection", "fit_response", "phase_correction",
    "TriangulationResult", "triangulate_ray_plane", "triangulate_ray_ray", "triangulate", "range_normals",
    "discontinuity_mask",
    "NoiseModel", "fit_noise_model", "phase_coordinate_std", "GRAY_CODE_STD", "along_ray_jacobian", "point_sigma",
]
