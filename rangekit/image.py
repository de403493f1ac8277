"""Image conversions shared by every algorithm: one rule for turning RGB into grey.

Grey is the plain mean of the three linear channels, ``(R + G + B) / 3``: the rule photometric stereo
needs (a Lambertian pixel's grey is then the albedo-weighted mean of its channels, and RGB albedos
average to the grey albedo) and the one the coded-light decoder and the projector-response fit use.
"""

from __future__ import annotations

import numpy as np

from rangekit.errors import InputError

__all__ = ["to_grey"]


def to_grey(rgb: np.ndarray) -> np.ndarray:
    """Mean of the colour channels: (..., 3) RGB of any real dtype -> (...) float32 grey.

    Linear intensity in, linear intensity out, in the input's units (uint8 255 stays 255.0). The last
    axis must be the three channels; callers that also accept grey images test ``ndim`` first.
    """
    a = np.asarray(rgb)
    if a.ndim < 1 or a.shape[-1] != 3:
        raise InputError(f"to_grey: expected RGB with 3 channels on the last axis, found shape {a.shape}")
    return a.mean(axis=-1, dtype=np.float32)
