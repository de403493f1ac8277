"""The names of ``rangekit.coded``, each loaded from its module on first use (rangekit._runtime.lazy.attach_stub)."""

from .patterns import (PatternSpec as PatternSpec, PATTERN_METHODS as PATTERN_METHODS,
    make_pattern_spec as make_pattern_spec, gray_encode as gray_encode, gray_decode as gray_decode,
    n_bits_for as n_bits_for, de_bruijn as de_bruijn, DEBRUIJN_PALETTE as DEBRUIJN_PALETTE,
    debruijn_stripe_colours as debruijn_stripe_colours)
from .result import DecodeResult as DecodeResult
from .decode import decode as decode
from .debruijn import decode_debruijn as decode_debruijn
from .phase import phase_from_steps as phase_from_steps
from .response import (ResponseFit as ResponseFit, PhaseCorrection as PhaseCorrection,
    fit_response as fit_response, phase_correction as phase_correction)
from .triangulate import (TriangulationResult as TriangulationResult,
    triangulate_ray_plane as triangulate_ray_plane, triangulate_ray_ray as triangulate_ray_ray,
    triangulate as triangulate, range_normals as range_normals, discontinuity_mask as discontinuity_mask)
from .uncertainty import (NoiseModel as NoiseModel, fit_noise_model as fit_noise_model,
    phase_coordinate_std as phase_coordinate_std, GRAY_CODE_STD as GRAY_CODE_STD,
    along_ray_jacobian as along_ray_jacobian, point_sigma as point_sigma)
