"""The result every coded-light decoder returns (:func:`rangekit.coded.decode.decode`,
:func:`rangekit.coded.debruijn.decode_debruijn`): projector coordinates, confidence and rejection masks."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["DecodeResult"]


@dataclass(frozen=True, eq=False)
class DecodeResult:
    """Per-pixel projector coordinates of a capture, (H, W) maps in camera pixels."""

    proj_col: np.ndarray          # (H, W) float32 projector column u, NaN where invalid
    proj_row: np.ndarray          # (H, W) float32 projector row v, NaN where invalid or rows not coded
    confidence: np.ndarray        # (H, W) float32 in [0, 1]; 0 where invalid; higher is better
    shadow: np.ndarray            # (H, W) bool: white - black below shadow_threshold (projector light absent)
    low_contrast: np.ndarray      # (H, W) bool: lit, but the code's contrast is below min_contrast
    global_dominated: np.ndarray  # (H, W) bool: separated global light > max_global_ratio * direct light
    inconsistent: np.ndarray      # (H, W) bool: code outside the projector, code and phase disagree, or
                                  # (subpixel) no stripe edge on both sides
    direct: np.ndarray | None = None        # (H, W) float32 direct light, fraction of full scale
    global_light: np.ndarray | None = None  # (H, W) float32 global light, fraction of full scale
    white: np.ndarray | None = None         # (H, W[, 3]) the white capture, for colour
    col_std: np.ndarray | None = None       # (H, W) float32 predicted std of proj_col, projector px; NaN where
                                            # invalid or unknown (rangekit.coded.uncertainty)
    row_std: np.ndarray | None = None       # (H, W) float32 the same for proj_row
    motion: np.ndarray | None = None        # (H, W) bool: the code mixes frames taken before and after the object
                                            # moved (rangekit.coded.motion; binary codes), rejected; None: unchecked
    moved_frames: tuple = ()                # the frames taken after it moved, where they could be named
    motion_unchecked: tuple = ()            # axes the motion check was asked for and could not check

    @property
    def valid(self) -> np.ndarray:
        """(H, W) bool: a projector column was decoded."""
        return np.isfinite(self.proj_col)

    def __repr__(self) -> str:
        n = self.proj_col.size
        return (f"DecodeResult({self.proj_col.shape[1]}x{self.proj_col.shape[0]}, valid={self.valid.sum() / n:.1%}, "
                f"shadow={self.shadow.sum() / n:.1%}, low_contrast={self.low_contrast.sum() / n:.1%}, "
                f"global={self.global_dominated.sum() / n:.1%}, inconsistent={self.inconsistent.sum() / n:.1%}"
                + self._motion_text(n) + ")")

    def _motion_text(self, n: int) -> str:
        unchecked = " and ".join(self.motion_unchecked)
        if self.motion is None:
            return f", motion=not checked ({unchecked})" if unchecked else ""
        return f", motion={self.motion.sum() / n:.1%}" + (f" ({unchecked} not checked)" if unchecked else "")

