"""Pulsed ToF: light returns after ``dt``, so the radial distance is ``r = c dt / 2`` (1 mm is 6.7 ps of
round trip)."""

from __future__ import annotations

import numpy as np

from rangekit.tof.plan import C_LIGHT

__all__ = ["pulsed_range"]


def pulsed_range(round_trip_s: np.ndarray) -> np.ndarray:
    """Radial distance ``r = c dt / 2`` in metres from round-trip times in seconds (NaN stays NaN)."""
    return 0.5 * C_LIGHT * np.asarray(round_trip_s, dtype=np.float64)
