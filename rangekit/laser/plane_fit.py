"""Robust plane fit to 3D points (the laser plane from its triangulated lines).

Method: least median of squares over random 3-point planes (robust to up to half outliers: stray peaks
off the board, interreflections), then total least squares (SVD of the centred inliers, the normal is the
smallest right singular vector) refitted while the inlier set changes. Inliers: ``|r| <= k sigma`` with
``sigma = 1.4826 * median|r|`` (the MAD scale of Gaussian residuals), ``k`` = 3 by default, never below
:data:`RESIDUAL_FLOOR` (1 nm; noise-free data would otherwise trim points on rounding).

Degenerate sets are refused (:class:`~rangekit.errors.CalibrationError`): fewer than 3 points, or points
that are (nearly) collinear, where the rotation of the plane about their line is not determined. The
test is on the spread (standard deviations along the principal axes, s1 >= s2 >= s3): collinear when
``s2 <= max(10 s3, 1e-6 s1)``, i.e. the set is not at least ten times wider across its line than it is
thick across the plane.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.errors import CalibrationError, InputError

__all__ = ["PlaneFit", "fit_plane", "tls_plane", "RESIDUAL_FLOOR"]

#: Smallest inlier threshold (metres), for noise-free data.
RESIDUAL_FLOOR = 1e-9
_SAMPLES = 256       # random 3-point planes tried
_SCORE_POINTS = 4000  # points the median is taken over (a fixed random subset of larger sets)


@dataclass(frozen=True, eq=False)
class PlaneFit:
    """A fitted plane.

    plane : (4,) ``[n, d]`` with ``n . X + d = 0``, |n| = 1 (same frame and units as the points).
    rms : RMS distance of the inliers from the plane (metres).
    n_inliers, n_points : inliers kept / finite points given.
    inliers : (N,) bool over the given rows (NaN rows False).
    spread : (3,) standard deviations of the inliers along their principal axes, largest first (metres):
        s1 along the set, s2 across it in the plane, s3 the thickness (about ``rms``).
    centroid : (3,) mean of the inliers.
    """

    plane: np.ndarray
    rms: float
    n_inliers: int
    n_points: int
    inliers: np.ndarray
    spread: np.ndarray
    centroid: np.ndarray

    @property
    def normal(self) -> np.ndarray:
        return self.plane[:3]

    def distances(self, points) -> np.ndarray:
        """(N,) signed distances of (N, 3) points from the plane."""
        return np.asarray(points, dtype=np.float64) @ self.plane[:3] + self.plane[3]

    def __repr__(self) -> str:
        return (f"PlaneFit(n={np.round(self.plane[:3], 6).tolist()}, d={self.plane[3]:.6f} m, rms "
                f"{self.rms * 1e3:.4f} mm, {self.n_inliers}/{self.n_points} inliers, spread "
                f"{np.round(self.spread * 1e3, 3).tolist()} mm)")


def tls_plane(P: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Total least squares plane of (N, 3) points: (plane (4,), spread (3,), centroid (3,))."""
    c = P.mean(axis=0)
    _, s, Vt = np.linalg.svd(P - c, full_matrices=False)
    n = Vt[-1]
    spread = np.zeros(3)
    spread[: len(s)] = s / np.sqrt(len(P))
    return np.append(n, -n @ c), spread, c


def _lmeds(P: np.ndarray, rng: np.random.Generator, groups: np.ndarray | None) -> np.ndarray | None:
    """Least-median-of-squares plane over random triples; None when every triple is degenerate.

    With ``groups`` of more than one label, triples never take all three points from one group, and a
    plane's score is the median over the groups of each group's median residual, so every group counts
    the same whatever its number of points (a pose with most of the points cannot impose its own plane).
    """
    n = len(P)
    sub = np.arange(n) if n <= _SCORE_POINTS else rng.choice(n, _SCORE_POINTS, replace=False)
    S = P[sub]
    idx = rng.integers(0, n, size=(4 * _SAMPLES, 3))
    labels = None
    if groups is not None and len(np.unique(groups)) > 1:
        g = groups[idx]
        idx = idx[~((g[:, 0] == g[:, 1]) & (g[:, 1] == g[:, 2]))]
        labels = groups[sub]
    idx = idx[:_SAMPLES]
    a, b, c = P[idx[:, 0]], P[idx[:, 1]], P[idx[:, 2]]
    normal = np.cross(b - a, c - a)
    norm = np.linalg.norm(normal, axis=1)
    ok = norm > 1e-12 * np.max(norm, initial=0.0)
    if not np.any(ok) or not np.max(norm) > 0:
        return None
    normal = normal[ok] / norm[ok, None]
    d = -np.einsum("ij,ij->i", normal, a[ok])
    r = np.abs(S @ normal.T + d)
    if labels is None:
        med = np.median(r, axis=0)
    else:
        med = np.median([np.median(r[labels == g], axis=0) for g in np.unique(labels)], axis=0)
    k = int(np.argmin(med))
    return np.append(normal[k], d[k])


def _degenerate(spread: np.ndarray) -> bool:
    s1, s2, s3 = spread
    return not s2 > max(10.0 * s3, 1e-6 * s1)


def fit_plane(points, *, k: float = 3.0, max_iterations: int = 10, seed: int = 0, groups=None,
              what: str = "points") -> PlaneFit:
    """Robust plane through (N, 3) points (module doc). NaN rows are ignored.

    Parameters
    ----------
    points : (N, 3) float64, metres (any frame).
    k : inlier threshold in robust standard deviations.
    max_iterations : refits of the inlier set.
    seed : of the random triples (the result is reproducible).
    groups : (N,) int labels (e.g. the board pose of each point) or None. Random planes are then never
        drawn through three points of one group: the points of one board pose lie exactly in the board's
        plane, which with two poses would hold half the points and win the median.
    what : names the points in errors ("laser 'laser0': points of poses 1, 2").

    Raises
    ------
    CalibrationError : fewer than 3 finite points, or a (nearly) collinear set.
    """
    P_all = np.asarray(points, dtype=np.float64)
    if P_all.ndim != 2 or P_all.shape[1] != 3:
        raise InputError(f"fit_plane: {what} must be an (N, 3) array, found shape {P_all.shape}")
    finite = np.all(np.isfinite(P_all), axis=1)
    P = P_all[finite]
    if groups is not None:
        groups = np.asarray(groups).reshape(-1)
        if groups.shape != (len(P_all),):
            raise InputError(f"fit_plane: groups must hold one label per point ({len(P_all)},), found shape "
                             f"{groups.shape}")
        groups = groups[finite]
    if len(P) < 3:
        raise CalibrationError(f"{what}: a plane needs at least 3 points, found {len(P)}")
    plane, spread, _ = tls_plane(P)
    if _degenerate(spread):
        raise CalibrationError(_collinear_message(what, spread, len(P)))
    start = _lmeds(P, np.random.default_rng(seed), groups)
    if start is not None:
        plane = start
    inl = np.ones(len(P), dtype=bool)
    for it in range(max(1, max_iterations)):
        r = np.abs(P @ plane[:3] + plane[3])
        sigma = 1.4826 * float(np.median(r))
        new = r <= max(k * sigma, RESIDUAL_FLOOR)
        if new.sum() < 3:
            break
        if it > 0 and np.array_equal(new, inl):
            break
        inl = new
        plane, _, _ = tls_plane(P[inl])
    plane, spread, centroid = tls_plane(P[inl])
    if _degenerate(spread):
        raise CalibrationError(_collinear_message(what, spread, int(inl.sum())))
    r = P[inl] @ plane[:3] + plane[3]
    inliers = np.zeros(len(P_all), dtype=bool)
    inliers[np.flatnonzero(finite)[inl]] = True
    return PlaneFit(plane=plane, rms=float(np.sqrt(np.mean(r * r))), n_inliers=int(inl.sum()), n_points=len(P),
                    inliers=inliers, spread=spread, centroid=centroid)


def _collinear_message(what: str, spread: np.ndarray, n: int) -> str:
    s = np.round(spread * 1e3, 4).tolist()
    return (f"{what}: the {n} points are (nearly) collinear (spread {s} mm along their principal axes; the "
            "second must be at least ten times the third): the plane's rotation about their line is not "
            "determined; add poses whose laser lines cross, not lie on one line")
