"""Synchronisation of relative poses over a view graph (Fusiello ch. 14.3): absolute poses of n views
from pairwise measurements, rotations first (spectral, eq. 14.11-14.18), then translations (linear least
squares on the incidence matrix, eq. 14.19-14.24), with an optional robust scheme against wrong edges.

Conventions. An edge ``(i, j, T_i_j)`` measures the pose of view j in view i's frame,
``T_i_j = inv(T_world_i) @ T_world_j`` (it maps view j's points into view i's frame), i.e.
``R_ij = R_i^T R_j`` and ``t_ij = R_i^T (t_j - t_i)`` with ``T_world_i = [R_i, t_i]``. The outputs are
the absolute ``T_world_view`` with world = view 0's frame (``T_world_view[0]`` is the identity).

Robust scheme (``robust=True``):

1. 3-cycle consistency: every edge gets the smallest cycle error over the triangles it closes
   (``R_ab R_bc R_ca ~ I``; for translations ``u_ab + u_bc + u_ca ~ 0``). Wrong edges never close a
   consistent triangle, so Cauchy weights of these scores start the iteration far from the outliers.
2. IRLS: weighted spectral synchronisation (or weighted least squares for translations), residual
   per edge, Cauchy weights with a MAD scale (``1.4826 * median |r|``), repeated until the weights settle.
3. A hard inlier test ``|r| <= 5 * scale``, then a last solve on the inliers with the user's weights
   only. The inliers must still connect every view to view 0 through edges that some cycle confirms:
   an edge that was on a cycle but became a bridge has a zero residual whatever its value (a view
   whose two edges disagree would keep one at random), so it does not count. Otherwise
   :class:`RegistrationError` names the views that were cut off.

Deterministic: no sampling.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.linalg import eigh
from scipy.sparse.linalg import spsolve
from scipy.spatial.transform import Rotation

from rangekit.errors import InputError, RegistrationError
from rangekit.geometry import make_T, nearest_rotation
from rangekit.registration.view_graph import (ViewGraph, check_connected, check_rejection, parse_view_graph,
                                              triangles)

__all__ = ["SyncResult", "RotationSync", "TranslationSync", "synchronise_rotations",
           "synchronise_translations", "synchronise", "synchronise_accepted"]

_INLIER_K = 5.0          # hard inlier threshold, in units of the MAD scale
_CAUCHY_C = 2.3849       # Cauchy kernel width in units of the scale (95 % efficiency under Gaussian noise)
_ANGLE_FLOOR = 1e-9      # radians: smallest residual scale (noise-free data)
_LENGTH_FLOOR = 1e-9     # relative to the median edge length: smallest translation residual scale
_WEIGHT_TOL = 1e-6       # IRLS stops when no weight changes by more


@dataclass(frozen=True, eq=False)
class SyncResult:
    """Absolute poses from relative ones. World = view 0's frame."""

    T_world_view: np.ndarray            # (n, 4, 4) float64 rigid; p_world = T_world_view[i] @ p_view_i
    edge_rotation_error: np.ndarray     # (E,) radians: angle between measured R_ij and R_i^T R_j; lower is better
    edge_translation_error: np.ndarray  # (E,) metres: |t_ij - R_i^T (t_j - t_i)| in view i's frame
    inlier: np.ndarray                  # (E,) bool: edges kept by the robust scheme (all True if robust=False)
    n_iterations: int                   # rotation + translation IRLS rounds
    method: str

    def __repr__(self) -> str:
        k = self.inlier
        rot = np.degrees(np.median(self.edge_rotation_error[k])) if k.any() else float("nan")
        tra = np.median(self.edge_translation_error[k]) if k.any() else float("nan")
        return (f"SyncResult(views={len(self.T_world_view)}, edges={len(k)}, inliers={int(k.sum())}, "
                f"median inlier error={rot:.4g} deg / {tra:.3e} m, iterations={self.n_iterations}, "
                f"method={self.method!r})")


class RotationSync(NamedTuple):
    R_world: np.ndarray      # (n, 3, 3) R_world_view, R_world[0] = I
    edge_error: np.ndarray   # (E,) radians
    inlier: np.ndarray       # (E,) bool


class TranslationSync(NamedTuple):
    t_world: np.ndarray      # (n, 3) metres: origin of each view in world, t_world[0] = 0
    edge_error: np.ndarray   # (E,) metres
    inlier: np.ndarray       # (E,) bool


# --------------------------------------------------------------------------- robust helpers
def _cauchy(r: np.ndarray, scale: float) -> np.ndarray:
    return 1.0 / (1.0 + (r / (_CAUCHY_C * scale)) ** 2)


def _mad_scale(r: np.ndarray, active: np.ndarray, floor: float) -> float:
    return max(1.4826 * float(np.median(r[active])), floor)


def _oriented(g: ViewGraph, e: np.ndarray, forward: np.ndarray) -> np.ndarray:
    """Measured relative rotations of edges ``e`` read from min to max view index."""
    R = g.R[e]
    return np.where(forward[:, None, None], R, np.transpose(R, (0, 2, 1)))


def _cycle_weights(g: ViewGraph, cycle_error: np.ndarray, tri: np.ndarray, active: np.ndarray,
                   floor: float) -> np.ndarray:
    """Initial weights: Cauchy of each edge's best 3-cycle error (1 for edges in no triangle)."""
    score = np.full(len(g.I), np.inf)
    for k in range(3):
        np.minimum.at(score, tri[:, k], cycle_error)
    in_tri = np.isfinite(score) & active
    if not in_tri.any():
        return np.ones(len(g.I))
    scale = _mad_scale(score, in_tri, floor)
    return np.where(in_tri, _cauchy(np.where(in_tri, score, 0.0), scale), 1.0)


# --------------------------------------------------------------------------- rotations
def _spectral(g: ViewGraph, w: np.ndarray) -> np.ndarray:
    """Weighted spectral rotation synchronisation (Fusiello eq. 14.11-14.18), R_world[0] = I."""
    n = g.n
    # Z has blocks w_ij R_ij (and their transposes), so Z X = D X for X = [R_1^T; ...; R_n^T].
    # With our convention R_ij = R_i^T R_j = X_i X_j^T. A lazy diagonal (Z_ii = d_i I) keeps the
    # spectrum of D^-1/2 Z D^-1/2 in [0, 2] with the sought eigenvalue 2 on top.
    Z = np.zeros((n, n, 3, 3))
    np.add.at(Z, (g.I, g.J), w[:, None, None] * g.R)
    np.add.at(Z, (g.J, g.I), w[:, None, None] * np.transpose(g.R, (0, 2, 1)))
    d = np.zeros(n)
    np.add.at(d, g.I, w)
    np.add.at(d, g.J, w)
    d = np.maximum(d, 1e-300)
    Z[np.arange(n), np.arange(n)] = d[:, None, None] * np.eye(3)
    Z = Z.transpose(0, 2, 1, 3).reshape(3 * n, 3 * n)
    s = np.repeat(1.0 / np.sqrt(d), 3)
    M = s[:, None] * Z * s[None, :]
    M = 0.5 * (M + M.T)
    _, Y = eigh(M, subset_by_index=[3 * n - 3, 3 * n - 1])
    X = (s[:, None] * Y).reshape(n, 3, 3)       # leading eigenvectors of (D kron I3)^-1 Z, by block
    if np.sum(np.linalg.det(X)) < 0:            # the basis may be a reflection: make the blocks det +1
        X = -X
    P = np.stack([nearest_rotation(Xi) for Xi in X])  # P_i ~ R_i^T Q, Q the unknown global rotation
    R_world = np.einsum("ij,nkj->nik", P[0], P)       # R_world_i = P_0 P_i^T = R_0^T R_i: view 0 is world
    R_world[0] = np.eye(3)
    return R_world


def _rotation_residuals(g: ViewGraph, R_world: np.ndarray) -> np.ndarray:
    D = np.transpose(g.R, (0, 2, 1)) @ np.transpose(R_world[g.I], (0, 2, 1)) @ R_world[g.J]  # R_ij^T R_i^T R_j
    return Rotation.from_matrix(D).magnitude()


def _irls(g: ViewGraph, solve, residuals, kw: np.ndarray, active: np.ndarray, floor: float, max_iterations: int):
    """Iteratively reweighted least squares with the Cauchy kernel from the weights ``kw``, then a hard inlier
    test at ``_INLIER_K`` scales and a final solve on the inliers. ``solve(edge_weights)`` gives the
    solution, ``residuals(solution)`` one residual per edge. Returns (solution, residuals, inlier, iterations)."""
    it = 0
    for it in range(1, max_iterations + 1):
        x = solve(g.w * active * kw)
        r = residuals(x)
        scale = _mad_scale(r, active, floor)
        new = _cauchy(r, scale)
        done = np.max(np.abs(new - kw)[active]) < _WEIGHT_TOL
        kw = new
        if done:
            break
    inlier = active & (r <= _INLIER_K * scale)
    check_rejection(g, active, inlier)
    x = solve(g.w * inlier)
    return x, residuals(x), inlier, it


def _rotation_sync(g: ViewGraph, robust: bool, max_iterations: int, active: np.ndarray):
    if not robust:
        R_world = _spectral(g, g.w * active)
        return R_world, _rotation_residuals(g, R_world), active.copy(), 1
    # 1. 3-cycle consistency.
    tri = triangles(g)
    kw = np.ones(len(g.I))
    if len(tri):
        fwd = [g.I[tri[:, k]] < g.J[tri[:, k]] for k in range(3)]
        C = (_oriented(g, tri[:, 0], fwd[0]) @ _oriented(g, tri[:, 1], fwd[1])
             @ np.transpose(_oriented(g, tri[:, 2], fwd[2]), (0, 2, 1)))  # R_ab R_bc R_ca ~ I
        ok = active[tri].all(axis=1)
        kw = _cycle_weights(g, np.where(ok, Rotation.from_matrix(C).magnitude(), np.inf), tri, active,
                            _ANGLE_FLOOR)
    # 2. IRLS on the spectral solution; 3. hard inlier test, connectivity, final solve on the inliers.
    return _irls(g, lambda w: _spectral(g, w), lambda R: _rotation_residuals(g, R), kw, active, _ANGLE_FLOOR,
                 max_iterations)


def synchronise_rotations(n: int, edges, *, robust: bool = True, weights=None,
                          max_iterations: int = 50) -> RotationSync:
    """Absolute rotations ``R_world_view`` from relative ones by spectral synchronisation.

    Parameters
    ----------
    n : int
        Number of views (indices 0..n-1).
    edges : sequence of (i, j, T_i_j) or dict {(i, j): T_i_j}
        Relative poses, ``T_i_j = inv(T_world_i) @ T_world_j`` as (4, 4) arrays (only the rotation is
        used here). One measurement per pair of views.
    robust : bool, optional
        3-cycle weighting, Cauchy IRLS and a hard inlier test (see the module docstring). If False,
        one weighted spectral solve with every edge.
    weights : (E,) array_like, optional
        Non-negative confidence per edge (0 drops it). Default: all 1.
    max_iterations : int, optional
        Maximum number of IRLS rounds.

    Returns
    -------
    RotationSync
        ``(R_world (n, 3, 3), edge_error (E,) radians, inlier (E,) bool)``; world = view 0.

    Raises
    ------
    InputError
        Bad edges (indices, shapes, non-rotations, duplicates), bad weights, or views not connected to
        view 0.
    RegistrationError
        The robust scheme rejected so many edges that some views lost their connection to view 0.
    """
    g = parse_view_graph(n, edges, weights, max_iterations)
    active = g.w > 0
    check_connected(g, active)
    R_world, err, inlier, _ = _rotation_sync(g, robust, max_iterations, active)
    return RotationSync(R_world, err, inlier)


# --------------------------------------------------------------------------- translations
def _solve_translations(g: ViewGraph, U: np.ndarray, w: np.ndarray) -> np.ndarray:
    """Weighted least squares for X B = U with t_0 = 0 (Fusiello eq. 14.19-14.24).

    Each edge says t_j - t_i = u_ij with u_ij = R_i t_ij (from t_ij = R_i^T (t_j - t_i)); B is the
    (n, E) incidence matrix (-1 at i, +1 at j). Normal equations (B W B^T) X^T = B W U^T, i.e. the
    weighted graph Laplacian, reduced by fixing view 0 at the origin.
    """
    n, E = g.n, len(g.I)
    B = sp.csr_matrix((np.r_[-np.ones(E), np.ones(E)], (np.r_[g.I, g.J], np.r_[np.arange(E), np.arange(E)])),
                      shape=(n, E))
    BW = B @ sp.diags(w)
    L = (BW @ B.T).tocsc()[1:, 1:]
    rhs = BW @ U
    t = np.zeros((n, 3))
    sol = spsolve(L, rhs[1:])
    t[1:] = sol.reshape(n - 1, 3)
    return t


def _translation_residuals(g: ViewGraph, U: np.ndarray, t: np.ndarray) -> np.ndarray:
    return np.linalg.norm(t[g.J] - t[g.I] - U, axis=1)  # = |t_ij - R_i^T (t_j - t_i)|


def _translation_sync(g: ViewGraph, R_world: np.ndarray, robust: bool, max_iterations: int, active: np.ndarray):
    U = np.einsum("eij,ej->ei", R_world[g.I], g.t)  # u_ij = R_i t_ij = t_j - t_i in world
    if not robust:
        t = _solve_translations(g, U, g.w * active)
        return t, _translation_residuals(g, U, t), active.copy(), 1
    lengths = np.linalg.norm(U[active], axis=1)
    floor = max(_LENGTH_FLOOR * float(np.median(lengths)), 1e-15)
    tri = triangles(g)
    kw = np.ones(len(g.I))
    if len(tri):
        sgn = [np.where(g.I[tri[:, k]] < g.J[tri[:, k]], 1.0, -1.0)[:, None] for k in range(3)]
        cyc = sgn[0] * U[tri[:, 0]] + sgn[1] * U[tri[:, 1]] - sgn[2] * U[tri[:, 2]]  # u_ab + u_bc - u_ac
        ok = active[tri].all(axis=1)
        kw = _cycle_weights(g, np.where(ok, np.linalg.norm(cyc, axis=1), np.inf), tri, active, floor)
    return _irls(g, lambda w: _solve_translations(g, U, w), lambda t: _translation_residuals(g, U, t), kw, active,
                 floor, max_iterations)


def _as_rotations(R_world, n: int) -> np.ndarray:
    R = np.asarray(R_world, dtype=np.float64)
    if R.shape != (n, 3, 3) or not np.all(np.isfinite(R)):
        raise InputError(f"sync: R_world must be a finite ({n}, 3, 3) array, found shape {R.shape}")
    return R


def synchronise_translations(n: int, edges, R_world, *, robust: bool = True, weights=None,
                             max_iterations: int = 50) -> TranslationSync:
    """Absolute view positions ``t_world`` from relative translations, given the absolute rotations.

    Solves ``t_j - t_i = R_i t_ij`` for every edge in the (robust) least-squares sense with view 0 at
    the origin. ``edges`` and ``weights`` as in :func:`synchronise_rotations`; ``R_world`` (n, 3, 3)
    are the ``R_world_view`` (e.g. from :func:`synchronise_rotations`), world = view 0.

    Returns
    -------
    TranslationSync
        ``(t_world (n, 3) metres, edge_error (E,) metres in view i's frame, inlier (E,) bool)``.

    Raises
    ------
    InputError, RegistrationError
        As :func:`synchronise_rotations`.
    """
    g = parse_view_graph(n, edges, weights, max_iterations)
    R = _as_rotations(R_world, g.n)
    active = g.w > 0
    check_connected(g, active)
    t, err, inlier, _ = _translation_sync(g, R, robust, max_iterations, active)
    return TranslationSync(t, err, inlier)


def synchronise(n: int, edges, *, robust: bool = True, weights=None, max_iterations: int = 50) -> SyncResult:
    """Absolute poses ``T_world_view`` of n views from relative poses ``T_i_j`` (world = view 0).

    Rotations by (robust) spectral synchronisation, then translations by (robust) least squares on
    the edges kept by the rotation step. Parameters as in :func:`synchronise_rotations`.

    Returns
    -------
    SyncResult
        Errors are reported for every edge (inliers or not) against the synchronised poses;
        ``inlier`` is True for edges kept by both the rotation and the translation step.

    Raises
    ------
    InputError, RegistrationError
        As :func:`synchronise_rotations`.
    """
    g = parse_view_graph(n, edges, weights, max_iterations)
    active = g.w > 0
    check_connected(g, active)
    R_world, rot_err, rot_in, it_r = _rotation_sync(g, robust, max_iterations, active)
    t_world, tr_err, tr_in, it_t = _translation_sync(g, R_world, robust, max_iterations, rot_in)
    T = np.stack([make_T(R, t) for R, t in zip(R_world, t_world)])
    T[0] = np.eye(4)
    method = ("robust spectral: 3-cycle weights, Cauchy IRLS (MAD scale), inlier test "
              f"|r| <= {_INLIER_K:g} scale" if robust else "spectral rotations, least-squares translations")
    return SyncResult(T_world_view=T, edge_rotation_error=rot_err, edge_translation_error=tr_err,
                      inlier=rot_in & tr_in, n_iterations=it_r + it_t, method=method)


def synchronise_accepted(n: int, edges) -> SyncResult:
    """:func:`synchronise` (robust) over the accepted ones of ``edges`` (each with ``i``, ``j``, ``T_i_j`` and
    ``accepted``, as :class:`rangekit.registration.pair_refine.EdgeResult`); RegistrationError when none is."""
    acc = [(e.i, e.j, e.T_i_j) for e in edges if e.accepted]
    if not acc:
        raise RegistrationError("no pair of views was registered reliably; the scans may not overlap")
    return synchronise(n, acc, robust=True)
