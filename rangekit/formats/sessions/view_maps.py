"""What a coded-light view's decoding leaves per camera pixel: the maps a session's view cache keeps
(``view_NNN/maps.npz``, :mod:`rangekit.app.process.view_cache`), which the TSDF fusion and the report read."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["ViewMaps"]


@dataclass(frozen=True, eq=False)
class ViewMaps:
    """What a view's decoding left, per camera pixel (H, W): for the TSDF fusion and the report."""

    proj_col: np.ndarray     # (H, W) float32 projector column, NaN where undecoded
    confidence: np.ndarray   # (H, W) float32 in [0, 1]
    depth: np.ndarray        # (H, W) float32 camera-frame z in metres, NaN where no point was kept
    capture: np.ndarray      # (H, W[, 3]) the capture under the white pattern, as read
    sigma: np.ndarray | None = None  # (H, W) float32 metres: predicted std along the camera ray, NaN where
                                     # no point was kept or no prediction (rangekit.coded.uncertainty)
