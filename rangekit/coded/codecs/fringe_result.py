"""What every fringe codec's decoder shares: the cue's unwrapping, the masks, and the DecodeResult.

Masks, per coded axis, from the fitted sinusoids (these codecs project no white or black frame; for a full
swing sinusoid ``2 B`` is the white - black signal):

- ``shadow``: the reference signal ``2 B`` (of the cue, or of the codec's own steps) below
  ``shadow_threshold`` of full scale;
- ``low_contrast``: lit, but the code's own signal (``2 B`` of the fringe; the modulated codec's direct
  light) below ``min_contrast``;
- ``inconsistent``: the codec's own check failed (the cue and the fringe disagree by more than
  :data:`CUE_TOLERANCE` of a period, the micro codec's periods match no column), or the column falls
  outside the projector.

``global_dominated`` stays False: these codecs measure no direct/global split that could reject a pixel.
``confidence`` is the code's signal as a fraction of full scale (0 where rejected); ``white`` is
``A + B`` of the reference, in the captures' dtype; ``col_std``/``row_std`` are NaN (no noise model yet).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rangekit.coded.result import DecodeResult
from rangekit.errors import DecodeError

__all__ = ["CUE_TOLERANCE", "unwrap_with_cue", "AxisMaps", "assemble"]

#: Largest |fringe column - cue column| accepted, as a fraction of the fringe period. Unwrapping picks the
#: wrong period once the cue is off by half a period; at a quarter the pixel is already suspect.
CUE_TOLERANCE = 0.25


def unwrap_with_cue(wrapped: np.ndarray, period: float, cue: np.ndarray, tolerance: float = CUE_TOLERANCE
                    ) -> tuple[np.ndarray, np.ndarray]:
    """(absolute coordinate, disagreeing) from a coordinate known modulo ``period`` (``wrapped``, projector px
    in [0, period)) and a coarse absolute one (``cue``): the period nearest the cue; ``disagreeing`` where the
    two still differ by more than ``tolerance`` periods. (H, W) float32 and bool."""
    p = np.float32(period)
    k = np.rint((cue - wrapped) / p)
    value = (wrapped + k * p).astype(np.float32)
    return value, ~(np.abs(value - cue) <= np.float32(tolerance) * p)


@dataclass
class AxisMaps:
    """One decoded axis before the masks are combined (all (H, W))."""

    value: np.ndarray            # float32 projector coordinate
    signal: np.ndarray           # float32 the code's own signal (white - black equivalent), raw units
    reference: np.ndarray        # float32 the reference signal the shadow test reads, raw units
    inconsistent: np.ndarray     # bool: the codec's own check failed
    white: np.ndarray            # float32 A + B of the reference, raw units
    direct: np.ndarray | None = field(default=None)  # float32 direct light, raw units, where measured


def assemble(axes: dict[str, AxisMaps], size: dict[str, int], *, dtype, full_scale: float, min_contrast: float,
             shadow_threshold: float) -> DecodeResult:
    """The DecodeResult of the decoded ``axes`` ("columns"/"rows" -> AxisMaps), masks as in the module doc.

    ``size``: the projector's pixels along each axis. Raises DecodeError if no pixel is lit.
    """
    first = next(iter(axes.values()))
    H, W = first.value.shape
    fs = np.float32(full_scale)
    shadow = np.zeros((H, W), bool)
    low = np.zeros((H, W), bool)
    incons = np.zeros((H, W), bool)
    conf = np.ones((H, W), np.float32)
    for axis, a in axes.items():
        shadow |= ~(a.reference >= np.float32(shadow_threshold) * fs)
        low |= ~(a.signal >= np.float32(min_contrast) * fs)
        incons |= a.inconsistent | ~((a.value >= -0.5) & (a.value <= np.float32(size[axis] - 0.5)))
        conf = np.minimum(conf, np.clip(a.signal / fs, 0, 1))
    if not np.any(~shadow):
        raise DecodeError(f"no pixel is lit: the fringes' signal is below {shadow_threshold:.0%} of full scale "
                          f"({shadow_threshold * full_scale:.0f}) everywhere; was the projector on and the capture "
                          "exposed?")
    low &= ~shadow
    incons &= ~(shadow | low)
    ok = ~(shadow | low | incons)
    nan = np.float32(np.nan)
    maps = {axis: np.where(ok, a.value, nan).astype(np.float32) for axis, a in axes.items()}
    none = lambda: np.full((H, W), nan, np.float32)  # noqa: E731
    top = np.iinfo(dtype).max if np.issubdtype(dtype, np.integer) else np.inf
    white = np.clip(np.rint(first.white), 0, top).astype(dtype)
    direct = None if first.direct is None else (first.direct / fs).astype(np.float32)
    return DecodeResult(proj_col=maps["columns"] if "columns" in maps else none(),
                        proj_row=maps["rows"] if "rows" in maps else none(),
                        confidence=np.where(ok, conf, 0).astype(np.float32), shadow=shadow, low_contrast=low,
                        global_dominated=np.zeros((H, W), bool), inconsistent=incons, direct=direct, white=white,
                        col_std=none(), row_std=none())
