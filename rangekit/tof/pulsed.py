"""Pulsed ToF: light returns after ``dt``, so the radial distance is ``r = c dt / 2`` (1 mm is 6.7 ps of
round trip)."""

from __future__ import annotations

import numpy as np

from rangekit.errors import InputError
from rangekit.tof.plan import C_LIGHT

__all__ = ["pulsed_range", "round_trip_problem", "MAX_ROUND_TRIP_S"]

#: Longest round trip accepted: 100 microseconds, 15 km of range. Longer ones are a unit mistake
#: (nanoseconds or picoseconds stored as seconds), not a return.
MAX_ROUND_TRIP_S = 1e-4


def round_trip_problem(round_trip_s) -> str | None:
    """Why ``round_trip_s`` (H, W) cannot be round-trip times in seconds, or None.

    NaN means "no return" and is fine. Refused: a type that is not floating point, infinite, negative or
    longer than :data:`MAX_ROUND_TRIP_S` values (each reported with the number of pixels and the extreme).
    """
    dt = np.asarray(round_trip_s)
    if dt.dtype.kind != "f":
        return f"expected floating-point round-trip times in seconds (NaN for no return), found type {dt.dtype}"
    checks = (("infinite", np.isinf(dt)), ("negative", dt < 0), ("too long", dt > MAX_ROUND_TRIP_S))
    with np.errstate(invalid="ignore"):
        for what, bad in checks:
            n = int(np.count_nonzero(bad))
            if n:
                extreme = dt[bad].min() if what == "negative" else dt[bad].max()
                return (f"{n} of {dt.size} pixels have {what} round-trip times (extreme {extreme:.4g} s); "
                        f"expected times in [0, {MAX_ROUND_TRIP_S:g}] s (up to 15 km), NaN where nothing returned")
    return None


def pulsed_range(round_trip_s: np.ndarray) -> np.ndarray:
    """Radial distance ``r = c dt / 2`` in metres from round-trip times in seconds (NaN stays NaN).

    Raises
    ------
    InputError
        If the times are not floating point, or some are infinite, negative or longer than
        :data:`MAX_ROUND_TRIP_S` (see :func:`round_trip_problem`).
    """
    problem = round_trip_problem(round_trip_s)
    if problem:
        raise InputError(f"pulsed_range: {problem}")
    return 0.5 * C_LIGHT * np.asarray(round_trip_s, dtype=np.float64)
