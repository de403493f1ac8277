"""The checks of ``session.json``'s fields (:mod:`rangekit.formats.sessions.session`): each names session.json, the
field, what was expected and what was found (a :class:`~rangekit.errors.ConfigError`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rangekit.errors import ConfigError

__all__ = ["MAX_VIEWS", "MAX_SEED", "MAX_WAIT_S", "MAX_ANGLE_RAD", "MAX_EXPOSURES", "MAX_PASSES", "SHA256_HEX",
           "show", "error", "fields", "integer", "number", "pass_motions"]

#: Bounds of the manifest's numbers: views per session, the noise seed (numpy's range), a wait in seconds,
#: an angle in radians, exposures of a multi-exposure view, turntable passes (the object turned over between).
MAX_VIEWS = 3600
MAX_SEED = 2**32 - 1
MAX_WAIT_S = 3600.0
MAX_ANGLE_RAD = 1e3
MAX_EXPOSURES = 8
MAX_PASSES = 8
SHA256_HEX = frozenset("0123456789abcdef")


def show(found) -> str:
    """``repr(found)``, at most 80 characters."""
    try:
        text = repr(found)
    except ValueError:  # an integer too long to print
        return "an integer of more than 4300 digits"
    return text if len(text) <= 80 else text[:77] + "..."


def error(path: Path, key: str, expected: str, found) -> ConfigError:
    return ConfigError(f"{path}: {key}: expected {expected}, found {show(found)}")


def fields(value, path: Path, key: str, required: tuple[str, ...], optional: tuple[str, ...] = ()) -> dict:
    """``value`` as an object holding every ``required`` key and no key beyond ``optional``."""
    expected = "an object with " + ", ".join(required) + (f" (and {', '.join(optional)})" if optional else "")
    if not isinstance(value, dict):
        raise error(path, key, expected, value)
    missing = [k for k in required if k not in value]
    unknown = [k for k in value if k not in required + optional]
    if missing or unknown:
        problem = (f"missing {', '.join(map(repr, missing))}" if missing else
                   f"unknown field(s) {', '.join(show(k) for k in unknown)}")
        raise ConfigError(f"{path}: {key}: expected {expected}; {problem}")
    return value


def integer(value, path: Path, key: str, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise error(path, key, f"an integer in {lo}..{hi}", value)
    return value


def number(value, path: Path, key: str, lo: float, hi: float) -> float:
    """A finite JSON number in [lo, hi] (lo, hi finite), as float."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not lo <= value <= hi:
        raise error(path, key, f"a finite number in [{lo:g}, {hi:g}]", value)
    return float(value)


def pass_motions(value, path: Path, key: str, n_passes: int) -> tuple:
    """``n_passes`` rigid motions (4, 4) as nested tuples (the simulator's turn-over of each pass, ground truth:
    rotation orthonormal with determinant 1 to 1e-9, last row 0 0 0 1, translations within 10 m)."""
    expected = f"{n_passes} rigid motions (4x4 lists, one per pass)"
    if not isinstance(value, list) or len(value) != n_passes:
        raise error(path, key, expected, value)
    out = []
    for i, m in enumerate(value):
        try:
            T = np.array(m, dtype=np.float64)
        except (TypeError, ValueError):
            T = None
        ok = T is not None and T.shape == (4, 4) and np.all(np.isfinite(T))
        if ok:
            R = T[:3, :3]
            ok = (np.allclose(R @ R.T, np.eye(3), atol=1e-9) and abs(np.linalg.det(R) - 1) < 1e-9
                  and np.array_equal(T[3], [0.0, 0.0, 0.0, 1.0]) and np.all(np.abs(T[:3, 3]) <= 10.0))
        if not ok:
            raise error(path, f"{key}[{i}]", "a rigid motion: a 4x4 list, rotation and translation (metres)", m)
        out.append(tuple(tuple(float(x) for x in row) for row in T))
    return tuple(out)
