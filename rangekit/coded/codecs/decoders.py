"""One entry for the fringe codecs: the capture stack in, each coded axis decoded by its method's module, the
masks and the DecodeResult assembled (:mod:`rangekit.coded.codecs.fringe_result`)."""

from __future__ import annotations

import numpy as np

from rangekit.coded.codecs.fringe_result import assemble
from rangekit.coded.codecs.fringes import SINUS_METHODS
from rangekit.coded.codecs.micro import decode_micro_axis
from rangekit.coded.codecs.modulated import decode_modulated_axis
from rangekit.coded.codecs.sinusoidal import decode_sinusoidal_axis
from rangekit.coded.frames import CaptureStack
from rangekit.coded.patterns import PatternSpec
from rangekit.coded.result import DecodeResult
from rangekit.rig.projector_response import ProjectorResponse

__all__ = ["decode_fringes"]


def decode_fringes(stack, spec: PatternSpec, *, order: str = "rangekit", min_contrast: float = 0.015,
                   shadow_threshold: float = 0.01, full_scale: float | None = None,
                   response: ProjectorResponse | None = None, workers: int = 0) -> DecodeResult:
    """Decode a ``micro``, ``modulated``, ``ftp``, ``psp`` or ``faps`` capture (arguments as
    :func:`rangekit.coded.decode.decode`, which calls this). Columns and rows as the spec codes them."""
    fr = CaptureStack(stack, spec, order)
    fs = float(full_scale if full_scale is not None else (255 if fr.dtype == np.uint8 else 65535))
    axes = {}
    for axis in spec.axes:
        if spec.method == "micro":
            axes[axis] = decode_micro_axis(fr, spec, axis, response)
        elif spec.method == "modulated":
            axes[axis] = decode_modulated_axis(fr, spec, axis, response)
        elif spec.method in SINUS_METHODS:
            axes[axis] = decode_sinusoidal_axis(fr, spec, axis, response, shadow_level=shadow_threshold * fs,
                                                workers=workers)
    return assemble(axes, {"columns": spec.width, "rows": spec.height}, dtype=fr.dtype, full_scale=fs,
                    min_contrast=min_contrast, shadow_threshold=shadow_threshold)
