"""Which pairs of views multi-view registration tries (the view graph's candidate edges).

A chooser is a function ``(T_world_view, prior) -> [(i, j), ...]`` (``i < j``): given the current poses
((n, 4, 4), world = the first view's frame) and whether they came from a prior, the pairs worth an
overlap test. Registration then keeps only the candidates whose overlap is real (``min_overlap``), so a
chooser only bounds the work: all pairs cost O(n^2) overlap tests, ICP runs and joint-refinement terms,
nearest neighbours O(n k).

- :func:`all_pairs`: every pair (no prior: the coarse poses may be anywhere).
- :func:`nearest_in_rotation`: each view with the ``k`` views whose poses differ least in rotation (on a
  turntable: the neighbours in angle, k / 2 on either side).
- :func:`default_pairs`: nearest 4 in rotation with a prior, all pairs without.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from rangekit.errors import InputError

__all__ = ["PairChooser", "all_pairs", "nearest_in_rotation", "default_pairs", "PRIOR_NEIGHBOURS"]

PairChooser = Callable[[np.ndarray, bool], list]

#: Neighbours per view with a prior: on the 12-view turntable (30 deg apart) the views 30 and 60 deg
#: away, 24 pairs instead of 66, at the same pose error (docs/benchmarks.md, registration).
PRIOR_NEIGHBOURS = 4


def all_pairs(T_world_view: np.ndarray, prior: bool = False) -> list[tuple[int, int]]:
    """Every pair ``(i, j)``, ``i < j``, of the ``len(T_world_view)`` views."""
    n = len(T_world_view)
    return [(i, j) for i in range(n) for j in range(i + 1, n)]


def _rotation_gaps(T_world_view: np.ndarray) -> np.ndarray:
    """(n, n) angle (radians) of the relative rotation between every two poses."""
    R = np.asarray(T_world_view, dtype=np.float64)[:, :3, :3]
    tr = np.einsum("iab,jab->ij", R, R)   # trace(R_i^T R_j)
    return np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0))


def nearest_in_rotation(k: int = PRIOR_NEIGHBOURS) -> PairChooser:
    """A chooser pairing each view with the ``k`` views (k >= 1) nearest to it in rotation (ties by
    index); the union over the views, so a view may get more than ``k`` pairs."""
    if not (isinstance(k, (int, np.integer)) and k >= 1):
        raise InputError(f"nearest_in_rotation: k must be an integer >= 1, found {k!r}")

    def choose(T_world_view: np.ndarray, prior: bool = False) -> list[tuple[int, int]]:
        gaps = _rotation_gaps(T_world_view)
        n = len(gaps)
        np.fill_diagonal(gaps, np.inf)
        out = set()
        for i in range(n):
            for j in np.argsort(gaps[i], kind="stable")[:min(k, n - 1)].tolist():
                out.add((min(i, j), max(i, j)))
        return sorted(out)

    return choose


def default_pairs(T_world_view: np.ndarray, prior: bool) -> list[tuple[int, int]]:
    """With a prior the :data:`PRIOR_NEIGHBOURS` nearest views in rotation, without one all pairs."""
    return nearest_in_rotation()(T_world_view, prior) if prior else all_pairs(T_world_view)
