"""How well two lasers' clouds of one object agree where both saw the same surface (issue 50: two lasers merged into
one object).

Each point of one cloud is compared with the local plane of its ``k`` nearest points of the other (their centroid
and smallest principal direction): the distance along that normal, so that the two clouds' different sampling (each
laser's profiles lie on other curves of the surface) does not count, only their offset across the surface. Only
points whose nearest point of the other cloud is within ``radius`` count: the overlap.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.errors import InputError

__all__ = ["Agreement", "laser_agreement"]


@dataclass(frozen=True)
class Agreement:
    """``rms``, ``median`` (metres): the points' distances to the other cloud's local surface, both ways;
    ``n``: the points compared (in the overlap)."""

    rms: float
    median: float
    n: int

    def line(self) -> str:
        return (f"the two lasers' points {self.rms * 1e3:.4f} mm RMS from each other's surface (median "
                f"{self.median * 1e3:.4f} mm, {self.n:,} points where both saw it)")


def _one_way(P: np.ndarray, Q: np.ndarray, k: int, radius: float) -> np.ndarray:
    """Distances (signed, each along its own local normal) of the points of ``P`` within ``radius`` of ``Q`` to
    ``Q``'s local planes."""
    from scipy.spatial import cKDTree

    dist, idx = cKDTree(Q).query(P, k=k)
    near = dist[:, 0] <= radius
    if not near.any():
        return np.zeros(0)
    N = Q[idx[near]]                                   # (m, k, 3)
    c = N.mean(axis=1)
    X = N - c[:, None, :]
    _, _, Vt = np.linalg.svd(X, full_matrices=False)
    n = Vt[:, 2, :]                                    # the smallest direction: the local normal
    return np.einsum("ij,ij->i", P[near] - c, n)


def laser_agreement(a, b, *, k: int = 8, radius: float = 5e-4) -> Agreement:
    """Compare the (N, 3) and (M, 3) clouds ``a`` and ``b`` (metres, one frame) where they overlap (module doc).

    Raises InputError for clouds that are not (N, 3) with at least ``k`` points, or that never come within
    ``radius`` of each other."""
    A, B = (np.asarray(x, dtype=np.float64) for x in (a, b))
    for name, X in (("a", A), ("b", B)):
        if X.ndim != 2 or X.shape[1] != 3 or len(X) < k:
            raise InputError(f"laser_agreement: {name} must be an (N, 3) cloud of at least {k} points, found shape "
                             f"{X.shape}")
    d = np.concatenate([np.abs(_one_way(A, B, k, radius)), np.abs(_one_way(B, A, k, radius))])
    if not len(d):
        raise InputError(f"laser_agreement: the two clouds never come within {radius * 1e3:g} mm of each other: no "
                         "surface both lasers saw")
    return Agreement(rms=float(np.sqrt(np.mean(d ** 2))), median=float(np.median(d)), n=int(len(d)))
