"""Multi-view ICP (Fusiello ch. 15): every pose refined at once by Gauss-Newton on the point-to-plane
residuals of all overlapping pairs, optionally keeping each view's start pose along the motions that no
overlap of that view constrains (rangekit.registration.stability).

Poses: ``T_world_view`` maps a view's points into the world, which is the first view's frame.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np
from scipy.spatial import cKDTree

from rangekit._runtime.executor import worker_count
from rangekit.errors import RegistrationError
from rangekit.geometry import apply_T, invert_T, make_T, rotvec_to_R
from rangekit.registration.icp import MIN_NORMAL_COS
from rangekit.surface.cloud import PointCloud

__all__ = ["JointResult", "refine_jointly", "pair_matches", "joint_samples", "FirstMatches"]

#: ``first(i, j, T_i, T_j, cloud_i, tree_i, samples_j, max_distance)``: directed pair (target ``i``, source ``j``)'s
#: correspondences at the start poses, found ahead (:func:`pair_matches`' ``(idx, ok)``), or None: find them.
FirstMatches = Callable[..., "tuple[np.ndarray, np.ndarray] | None"]


@dataclass(frozen=True, eq=False)
class JointResult:
    T_world_view: np.ndarray    # (n, 4, 4)
    rmse: float                 # weighted point-to-plane RMS over all pairs, metres
    n_iterations: int
    converged: bool
    pair_rmse: dict             # (i, j) -> RMS residual of that pair, metres


def refine_jointly(clouds: Sequence[PointCloud], T_world_view: np.ndarray, pairs: Sequence[tuple[int, int]], *,
                   max_distance: float, iterations: int = 15, samples: int = 8000, kernel_k: float = 1.345,
                   tolerance: float = 1e-9, rng: int = 0, hold: dict | None = None,
                   basis: Callable[[np.ndarray, np.ndarray, float], np.ndarray] | None = None,
                   trees: Sequence[cKDTree] | None = None, workers: int = 0,
                   first: FirstMatches | None = None) -> JointResult:
    """Multi-view ICP: refine every pose at once (view 0 fixed) by Gauss-Newton on point-to-plane residuals
    of all overlapping ``pairs`` in both directions, re-associating closest points each iteration.

    The residual of a source point p (view j) and its closest target point q (view i, normal n), in world
    coordinates, is ``n . (T_j p - T_i q)``; small motions ``xi_k = (omega_k, v_k)`` of every pose about the
    scene centroid enter linearly, Huber weights use a MAD scale, and the 6(n-1) normal equations are solved
    densely. Unlike synchronising pairwise results, every correspondence weighs in directly.

    ``hold``: ``{view: [HeldMotions in world, one per pair of that view]}`` (see
    :mod:`rangekit.registration.stability`): a view keeps its start pose along the motions that every
    one of its pairs leaves free; every other motion is solved as usual (:func:`_held_basis`).

    ``basis(T_world_view, centre, length)``: instead, the updates lie in the span of the (6(n-1), m)
    matrix it returns at each iteration (e.g. :func:`rangekit.registration.turntable.turntable_basis`:
    every view rotated about one common axis); ``hold`` is then not used.

    ``trees``: each cloud's k-d tree of its points, when built already. ``workers``: threads that find the
    directed pairs' correspondences (the k-d tree queries release the GIL); the result does not depend on it.
    ``first``: the first iteration's correspondences of a directed pair found ahead (:data:`FirstMatches`, a scan's
    :meth:`rangekit.registration.ahead.RegistrationAhead.first_matches`: they depend on the start poses, the two
    clouds and the samples only); the result is the same bits with or without it.
    """
    n = len(clouds)
    T = np.array(T_world_view, dtype=np.float64, copy=True)
    gen = np.random.default_rng(rng)
    trees = list(trees) if trees is not None else [cKDTree(c.points) for c in clouds]
    picks = [joint_samples(gen, len(c.points), samples) for c in clouds]
    subs = [c.points[k] for c, k in zip(clouds, picks)]
    sub_normals = [None if c.normals is None else c.normals[k] for c, k in zip(clouds, picks)]
    centre = np.mean([apply_T(T[k], c.points.mean(axis=0, keepdims=True))[0] for k, c in enumerate(clouds)], axis=0)
    directed = [(i, j) for i, j in pairs] + [(j, i) for i, j in pairs]
    size = float(np.sqrt(np.mean([np.sum((apply_T(T[k], s) - centre) ** 2, axis=1).mean() for k, s in enumerate(subs)])))
    converged, it, rmse, pair_rmse = False, 0, float("nan"), {}
    with ThreadPoolExecutor(max_workers=worker_count(int(workers)), thread_name_prefix="rangekit-joint") as pool:
        for it in range(1, iterations + 1):
            Hm = np.zeros((6 * n, 6 * n))
            g = np.zeros(6 * n)
            # Each directed pair's correspondences on its own (the k-d tree queries release the GIL), two at a time,
            # taken in order: the same sums in the same order as one after another.
            ask = first if it == 1 and first is not None else None

            def terms_of(ij, ask=ask):
                i, j = ij
                match = None if ask is None else ask(i, j, T[i], T[j], clouds[i], trees[i], subs[j], max_distance)
                return _pair_terms(i, j, T[i], T[j], clouds, trees, subs, sub_normals, centre, max_distance, match)

            terms = [x for x in pool.map(terms_of, directed) if x is not None]
            res_all = [x[:5] for x in terms]
            pair_rmse = {(min(i, j), max(i, j)): rmse_ij for i, j, _, _, _, rmse_ij in terms}
            if not res_all:
                raise RegistrationError("joint refinement: no pair has correspondences within max_distance")
            r_cat = np.concatenate([x[2] for x in res_all])
            scale = max(1.4826 * np.median(np.abs(r_cat)), 1e-12)
            for i, j, r, Ji, Jj in res_all:
                a = np.abs(r) / scale
                w = np.minimum(1.0, kernel_k / np.maximum(a, 1e-12))  # Huber
                si, sj = slice(6 * i, 6 * i + 6), slice(6 * j, 6 * j + 6)
                Wi, Wj = Ji * w[:, None], Jj * w[:, None]
                Hm[si, si] += Ji.T @ Wi
                Hm[sj, sj] += Jj.T @ Wj
                Hm[si, sj] += Ji.T @ Wj
                Hm[sj, si] += Jj.T @ Wi
                g[si] += Wi.T @ r
                g[sj] += Wj.T @ r
            rmse = float(np.sqrt(np.mean(r_cat ** 2)))
            free = slice(6, 6 * n)
            A = Hm[free, free]
            B = basis(T, centre, size) if basis is not None else (_held_basis(n, hold, centre, size) if hold else None)
            try:
                if B is None:
                    xi = -np.linalg.solve(A + 1e-12 * np.trace(A) / len(A) * np.eye(len(A)), g[free])
                else:
                    Ab = B.T @ A @ B
                    xi = -B @ np.linalg.solve(Ab + 1e-12 * np.trace(Ab) / len(Ab) * np.eye(len(Ab)), B.T @ g[free])
            except np.linalg.LinAlgError as exc:
                raise RegistrationError("joint refinement: the view graph does not constrain every pose") from exc
            step = 0.0
            for k in range(1, n):
                om, v = xi[6 * (k - 1): 6 * (k - 1) + 3], xi[6 * (k - 1) + 3: 6 * k]
                R = rotvec_to_R(om)
                dT = make_T(R, v + centre - R @ centre)  # rotation about the centroid, then translation
                T[k] = dT @ T[k]
                step = max(step, np.linalg.norm(v) + np.linalg.norm(om) * np.linalg.norm(np.ptp(subs[k], axis=0)))
            if step < tolerance:
                converged = True
                break
    return JointResult(T, rmse, it, converged, pair_rmse)


def pair_matches(T_i_j: np.ndarray, p_j: np.ndarray, normals_j: np.ndarray | None, cloud_i: PointCloud,
                 tree_i: cKDTree, max_distance: float) -> tuple[np.ndarray, np.ndarray]:
    """The correspondences of source samples ``p_j`` (m, 3; ``normals_j`` theirs or None) in target ``cloud_i``
    (``tree_i`` its k-d tree) with the source at ``T_i_j``: ``(idx (m,), ok (m,) bool)``, each sample's closest
    target point and whether it lies within ``max_distance`` (metres) and faces the same way."""
    d, idx = tree_i.query(apply_T(T_i_j, p_j), k=1, distance_upper_bound=max_distance, workers=1)
    ok = np.isfinite(d)
    if normals_j is not None:
        # Only surfaces facing the same way: the two faces of a thin part (a fin, a sheet) are
        # closer than the gate but are not the same surface.
        n_src = normals_j @ T_i_j[:3, :3].T
        ok[ok] = np.einsum("ij,ij->i", n_src[ok], cloud_i.normals[idx[ok]]) > MIN_NORMAL_COS
    return idx, ok


def _pair_terms(i: int, j: int, T_i: np.ndarray, T_j: np.ndarray, clouds: Sequence[PointCloud], trees: Sequence,
                subs: list, sub_normals: list, centre: np.ndarray, max_distance: float, match=None):
    """The residuals and Jacobians of directed pair (target ``i``, source ``j``) at poses ``T_i``, ``T_j``:
    ``(i, j, r (m,), Ji (m, 6), Jj (m, 6), rms of r)`` over view j's sample points whose closest point in
    view i lies within ``max_distance`` (metres) and faces the same way (:func:`pair_matches`, or ``match``, its
    result found ahead); None with fewer than 10."""
    p_j = subs[j]
    idx, ok = match if match is not None else \
        pair_matches(invert_T(T_i) @ T_j, p_j, sub_normals[j], clouds[i], trees[i], max_distance)
    if np.count_nonzero(ok) < 10:
        return None
    pw = apply_T(T_j, p_j[ok]) - centre
    qw = apply_T(T_i, clouds[i].points[idx[ok]]) - centre
    nw = clouds[i].normals[idx[ok]] @ T_i[:3, :3].T
    r = np.einsum("ij,ij->i", pw - qw, nw)
    Jj = np.hstack([np.cross(pw, nw), nw])
    Ji = -np.hstack([np.cross(qw, nw), nw])
    return i, j, r, Ji, Jj, float(np.sqrt(np.mean(r ** 2)))


def _held_basis(n: int, hold: dict, centre: np.ndarray, length: float) -> np.ndarray | None:
    """(6(n-1), m) basis of the updates ``xi = (omega, v)`` (about ``centre``) of views 1..n-1 that leave
    each held view's free motions alone, or None when no view is held.

    ``hold[k]``: HeldMotions in world of every pair of view k (unit ``(L omega, t)`` about their own
    centre). A motion is free for view k only if each of its pairs leaves it free: the held subspace is
    the intersection of the pairs' subspaces (directions within about 25 degrees of all of them), in the
    scaled coordinates ``z = (length * omega, v)``.
    """
    blocks, held = [], False
    for k in range(1, n):
        Q = None
        for h in hold.get(k, []):
            M = np.asarray(h.motions, dtype=np.float64).reshape(-1, 6)
            omega = M[:, :3] / h.length
            v = M[:, 3:] + np.cross(omega, centre - h.centre)  # the same motion about ``centre``
            Z = np.linalg.svd(np.hstack([omega * length, v]).T, full_matrices=False)[0]
            if Q is None:
                Q = Z
            else:
                U, sv, _ = np.linalg.svd(Q.T @ Z, full_matrices=False)
                Q = Q @ U[:, sv > 0.9]
        if Q is None or Q.shape[1] == 0:
            blocks.append(np.eye(6))
            continue
        B = np.linalg.svd(Q.T, full_matrices=True)[2][Q.shape[1]:].T   # the complement, z coordinates
        B[:3] /= length                                                 # as xi = (omega, v)
        blocks.append(B)
        held = True
    if not held:
        return None
    B = np.zeros((6 * (n - 1), sum(b.shape[1] for b in blocks)))
    col = 0
    for k, b in enumerate(blocks):
        B[6 * k: 6 * k + 6, col: col + b.shape[1]] = b
        col += b.shape[1]
    return B


def joint_samples(gen: np.random.Generator, n_points: int, samples: int) -> np.ndarray:
    """The indices of the points of a view (``n_points``) the joint refinement samples, drawn from ``gen``, which
    draws each view's in turn (the first view's first): at most ``samples``, without repeats."""
    return gen.choice(n_points, min(samples, n_points), replace=False)
