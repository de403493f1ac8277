"""Generalised Procrustes Analysis: bring m point sets of the same N landmarks into one frame at once
(Fusiello ch. 15, eq. 15.1-15.3 and Listing 15.1; Commandeur 1991; Crosilla & Beinat 2002 for missing data).

Each set is an (N, 3) array in its own frame; row k is landmark k in every set, a row of NaN marks a
landmark that set did not see. The result maps every set into the frame of set 0:
``p_world = T_world_set[i] @ p_set_i``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.errors import InputError, shown
from rangekit.geometry import apply_T, invert_T, procrustes, rotation_angle

__all__ = ["GPAResult", "gpa"]


@dataclass(frozen=True, eq=False)
class GPAResult:
    """Result of :func:`gpa`. World = the frame of set 0 (``T_world_set[0]`` is the identity)."""

    T_world_set: np.ndarray  # (m, 4, 4) float64 similarity (rigid when scale=False); p_world = T @ p_set
    centroid: np.ndarray     # (N, 3) float64 consensus shape in world; NaN for landmarks no set saw
    residuals: np.ndarray    # (m, N) float64 |T_world_set[i] @ B_i[k] - centroid[k]| in world units; NaN if missing
    rmse: float              # RMS of the residuals over all present landmarks (world units); lower is better
    n_iterations: int
    converged: bool
    reason: str = ""         # why it stopped

    @property
    def scales(self) -> np.ndarray:
        """(m,) isotropic scale of each ``T_world_set`` (all 1 for rigid GPA)."""
        return np.cbrt(np.linalg.det(self.T_world_set[:, :3, :3]))

    def __repr__(self) -> str:
        angles = [np.degrees(rotation_angle(T[:3, :3] / s)) for T, s in zip(self.T_world_set, self.scales)]
        return (f"GPAResult(sets={len(self.T_world_set)}, landmarks={len(self.centroid)}, "
                f"max angle={max(angles):.4f} deg, rmse={self.rmse:.3e}, iterations={self.n_iterations}, "
                f"converged={self.converged}, reason={self.reason!r})")


def _check_sets(point_sets) -> tuple[np.ndarray, np.ndarray]:
    """Stack the sets into (m, N, 3) and return it with the (m, N) presence mask."""
    try:
        sets = [np.asarray(B, dtype=np.float64) for B in point_sets]
    except (TypeError, ValueError) as exc:
        raise InputError(f"gpa: point_sets must be a sequence of (N, 3) float arrays ({exc})") from exc
    if len(sets) < 2:
        raise InputError(f"gpa: needs at least 2 point sets, found {len(sets)}")
    for i, B in enumerate(sets):
        if B.ndim != 2 or B.shape[1] != 3:
            raise InputError(f"gpa: set {i} must be an (N, 3) array, found shape {B.shape}")
        if B.shape[0] != sets[0].shape[0]:
            raise InputError(f"gpa: every set must list the same N landmarks (row k = landmark k); set 0 has "
                             f"{sets[0].shape[0]} rows, set {i} has {B.shape[0]}; mark missing landmarks "
                             f"with a row of NaN")
        if np.any(np.isinf(B)):
            raise InputError(f"gpa: set {i} has infinite coordinates (rows {np.flatnonzero(np.isinf(B).any(1))[:5]})")
        partial = np.isnan(B).any(axis=1) & ~np.isnan(B).all(axis=1)
        if np.any(partial):
            raise InputError(f"gpa: set {i} has rows with some but not all coordinates NaN "
                             f"(rows {np.flatnonzero(partial)[:5].tolist()}); a missing landmark is a row "
                             f"of three NaN")
    X = np.stack(sets)
    present = ~np.isnan(X[:, :, 0])
    for i, c in enumerate(present.sum(axis=1)):
        if c < 3:
            raise InputError(f"gpa: set {i} has {c} present landmarks; at least 3 non-collinear are needed")
    return X, present


def _check_weights(weights, present: np.ndarray) -> np.ndarray:
    m, N = present.shape
    if weights is None:
        return present.astype(np.float64)
    w = np.asarray(weights, dtype=np.float64)
    if w.shape == (m,):
        w = np.repeat(w[:, None], N, axis=1)
    if w.shape != (m, N):
        raise InputError(f"gpa: weights must have shape ({m},) or ({m}, {N}), found {w.shape}")
    if not np.all(np.isfinite(w)) or np.any(w < 0):
        raise InputError("gpa: weights must be finite and non-negative")
    w = np.where(present, w, 0.0)
    for i, c in enumerate(np.count_nonzero(w, axis=1)):
        if c < 3:
            raise InputError(f"gpa: set {i} has {c} present landmarks with positive weight; at least 3 needed")
    return w


def _transform_all(Ts: np.ndarray, X: np.ndarray) -> np.ndarray:
    """(m, N, 3): every set mapped through its own transform (NaN rows stay NaN)."""
    return np.einsum("mij,mnj->mni", Ts[:, :3, :3], X) + Ts[:, None, :3, 3]


def _centroid(Y: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Crosilla & Beinat: C_k = sum_i w_ik Y_ik / sum_i w_ik; NaN where no set has weight."""
    W = w.sum(axis=0)
    S = np.einsum("mn,mni->ni", w, np.nan_to_num(Y))
    with np.errstate(invalid="ignore", divide="ignore"):
        C = S / W[:, None]
    C[W <= 0] = np.nan
    return C


def _size(C: np.ndarray, w: np.ndarray) -> float:
    """Weighted RMS distance of the centroid's landmarks from their weighted mean."""
    v = w.sum(axis=0)
    ok = v > 0
    mu = v[ok] @ C[ok] / v[ok].sum()
    return float(np.sqrt(v[ok] @ np.sum((C[ok] - mu) ** 2, axis=1) / v[ok].sum()))


def _cost(Y: np.ndarray, C: np.ndarray, w: np.ndarray) -> float:
    d2 = np.sum((np.nan_to_num(Y) - np.nan_to_num(C)[None]) ** 2, axis=2)
    return float(np.sum(w * d2))


def _initial_alignment(X: np.ndarray, w: np.ndarray, scale: bool) -> np.ndarray:
    """Greedy sequential alignment: set 0 first, then always the set that shares the most landmarks
    (by weight) with the running centroid of the sets already placed."""
    m = X.shape[0]
    Ts = np.tile(np.eye(4), (m, 1, 1))
    placed = np.zeros(m, dtype=bool)
    placed[0] = True
    S = np.nan_to_num(X[0]) * w[0][:, None]
    W = w[0].copy()
    while not placed.all():
        overlap = np.where(placed, -1, np.count_nonzero((w > 0) & (W > 0)[None], axis=1))
        i = int(np.argmax(overlap))
        if overlap[i] < 3:
            lonely = np.flatnonzero(~placed).tolist()
            raise InputError(f"gpa: sets {lonely} share fewer than 3 landmarks with sets "
                             f"{shown(np.flatnonzero(placed))} (best overlap: {overlap[i]}), so they cannot be "
                             f"brought into one frame; check the landmark numbering or drop those sets")
        ok = W > 0
        C = np.full_like(S, np.nan)
        C[ok] = S[ok] / W[ok, None]
        try:
            fit = procrustes(X[i], C, weights=np.where(ok, w[i], 0.0), scale=scale)
        except InputError as exc:
            raise InputError(f"gpa: set {i} cannot be aligned to sets {shown(np.flatnonzero(placed))}: "
                             f"{exc}") from exc
        Ts[i] = fit.T_dst_src
        placed[i] = True
        S += np.nan_to_num(apply_T(Ts[i], X[i])) * w[i][:, None]
        W += w[i]
    return Ts


def gpa(point_sets, *, scale: bool = False, weights=None, max_iterations: int = 100,
        tol: float = 1e-12) -> GPAResult:
    """Generalised Procrustes Analysis of m corresponding point sets, with missing landmarks.

    Minimises ``sum_i sum_k w_ik |T_i B_ik - C_k|^2`` over the transforms ``T_i`` (rigid, or similarity
    when ``scale`` is True) and the consensus shape ``C`` by alternation (Commandeur; Fusiello
    Listing 15.1): the centroid of the aligned sets (Crosilla & Beinat's weighted mean per landmark,
    eq. 15.3), then every set aligned to the centroid by weighted Procrustes, until the cost stops
    decreasing. Starts from a greedy sequential alignment (set 0, then the set with the most shared
    landmarks, ...).

    Similarity GPA: scaling every set by the same factor scales the cost too, so the plain alternation
    would shrink everything towards a point. After each centroid update all transforms (and the
    centroid) are rescaled so that the centroid's weighted RMS size stays that of the initial
    alignment (i.e. of set 0); every set, set 0 included, is free during the iterations. The result is
    finally expressed in set 0's frame, where ``T_world_set[0]`` is the identity and the scales are
    relative to set 0.

    Parameters
    ----------
    point_sets : sequence of m (N, 3) array_like
        m >= 2 sets of the same N landmarks, each in its own frame (any length unit; the result uses the
        unit of set 0). A row of NaN marks a landmark missing from that set.
    scale : bool, optional
        Estimate an isotropic scale per set (similarity GPA). Default False (rigid).
    weights : (m, N) or (m,) array_like, optional
        Non-negative weight per landmark and set (or per set). Missing landmarks get weight 0 whatever
        is given. Default: 1 for every present landmark.
    max_iterations : int, optional
        Maximum number of centroid/alignment rounds.
    tol : float, optional
        Stop when the decrease of the normalised cost ``cost / (sum w * size^2)`` (dimensionless; size =
        the centroid's RMS radius) is below ``tol``.

    Returns
    -------
    GPAResult
        ``converged`` is False (with ``reason``) if ``max_iterations`` was reached first.

    Raises
    ------
    InputError
        Fewer than 2 sets, sets with different N, rows only partly NaN or infinite, a set with fewer
        than 3 present landmarks (or collinear ones), sets that share fewer than 3 landmarks with the
        rest, or bad weights.
    """
    X, present = _check_sets(point_sets)
    w = _check_weights(weights, present)
    if max_iterations < 1:
        raise InputError(f"gpa: max_iterations must be >= 1, found {max_iterations}")
    m = X.shape[0]

    # Initial alignment, then the reference size that fixes the scale gauge.
    Ts = _initial_alignment(X, w, scale)
    Y = _transform_all(Ts, X)
    C = _centroid(Y, w)
    size0 = _size(C, w)
    if not size0 > 0:
        raise InputError("gpa: all landmarks coincide after alignment; the sets have no spatial extent")
    norm = float(w.sum()) * size0 ** 2
    cost = _cost(Y, C, w) / norm

    converged = False
    reason = f"max_iterations={max_iterations} reached"
    it = 0
    for it in range(1, max_iterations + 1):
        # Align every set to the current centroid (Fusiello eq. 15.2, weighted Procrustes).
        for i in range(m):
            Ts[i] = procrustes(X[i], C, weights=w[i], scale=scale).T_dst_src
        # New centroid (eq. 15.3, Crosilla & Beinat with presence weights).
        Y = _transform_all(Ts, X)
        C = _centroid(Y, w)
        if scale:  # keep the consensus size fixed: no collapse towards a point
            alpha = size0 / _size(C, w)
            Ts[:, :3, :] *= alpha
            Y *= alpha
            C *= alpha
        new_cost = _cost(Y, C, w) / norm
        change = cost - new_cost
        cost = new_cost
        if abs(change) <= tol:
            converged = True
            reason = f"cost change {abs(change):.1e} <= tol={tol:.0e}"
            break

    # Express everything in set 0's frame.
    G = invert_T(Ts[0])
    T_world_set = np.einsum("ij,mjk->mik", G, Ts)
    T_world_set[0] = np.eye(4)
    Y = _transform_all(T_world_set, X)
    C = _centroid(Y, w)
    residuals = np.linalg.norm(Y - C[None], axis=2)
    residuals[~present] = np.nan
    ok = present & np.isfinite(residuals)
    rmse = float(np.sqrt(np.mean(residuals[ok] ** 2)))
    return GPAResult(T_world_set=T_world_set, centroid=C, residuals=residuals, rmse=rmse, n_iterations=it,
                     converged=converged, reason=reason)
