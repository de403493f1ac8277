"""Registration of many scans into one frame (Fusiello ch. 14.3 and 15).

1. Initial poses: a prior (e.g. the turntable's axis and angles) or, with none, coarse alignment of
   every pair (FPFH + RANSAC, ICP-verified) followed by robust synchronisation of the accepted pairs.
2. Refinement rounds: with the current poses, find the pairs that overlap, register each pair by ICP
   starting from the current relative pose, accept an edge only if its inlier RMSE is small and its
   overlap large enough (ICP "fitness" alone accepts symmetric flips), and synchronise rotations and
   translations robustly over the accepted edges.

Poses: ``T_world_view`` maps a view's points into the world, which is the first view's frame.
Relative edges are ``T_i_j`` (view j into view i).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Callable, Sequence

import numpy as np
from scipy.spatial import cKDTree

from rangekit.errors import RegistrationError
from rangekit.geometry import apply_T, invert_T, make_T, rotation_angle, rotvec_to_R
from rangekit.surface.cloud import PointCloud, bbox_diagonal, check_voxel, estimate_normals, voxel_downsample
from rangekit.registration.coarse import CoarseOptions, compute_features, coarse_align
from rangekit.registration.icp import IcpOptions, icp
from rangekit.registration.sync import SyncResult, synchronise

__all__ = ["MultiViewOptions", "EdgeResult", "MultiViewResult", "register_views", "pairwise_overlap",
           "JointResult", "refine_jointly", "overlap_rms"]


@dataclass(frozen=True)
class MultiViewOptions:
    """Settings; lengths in metres, ``None`` = derived from the data (voxel = bounding-box diagonal / 110)."""

    voxel: float | None = None           # coarse features and the first refinement round
    fine_voxel: float | None = None      # later rounds (default voxel / 3)
    min_overlap: float = 0.15            # fraction of a view's points within 2 voxels of the other
    max_rmse: float = 0.45               # accepted pairs: RMSE (2-voxel gate) below this many voxels
    max_coarse_rmse: float = 0.45        # coarse pairs: ICP-verified RMSE below this many voxels. Wrong
                                         # alignments (e.g. front/back flips) can keep 0.3-0.6 overlap but
                                         # not a low RMSE: on the bunny, right <= 0.36, wrong >= 0.64 voxel
    rounds: int = 1
    joint_iterations: int = 60           # joint multi-view refinement after synchronisation (0: none)
    joint_tolerance: float = 1e-7        # metres: stop when no pose moves a point by more
    joint_samples: int = 50000           # points per view in the joint refinement (at most all fine points)
    icp: IcpOptions = field(default_factory=lambda: IcpOptions(method="point_to_plane", kernel="huber",
                                                               max_iterations=60))
    rng: int = 0


@dataclass(frozen=True, eq=False)
class EdgeResult:
    """One pairwise registration in the view graph."""

    i: int
    j: int
    T_i_j: np.ndarray        # (4, 4) maps view j into view i
    rmse: float              # ICP inlier RMSE, metres
    overlap: float           # fraction of view j's points with a partner in view i
    accepted: bool
    reason: str = ""

    def __repr__(self) -> str:
        return (f"EdgeResult({self.i}-{self.j}, rmse={self.rmse * 1e3:.3f} mm, overlap={self.overlap:.2f}, "
                f"accepted={self.accepted}{', ' + self.reason if self.reason else ''})")


@dataclass(frozen=True, eq=False)
class MultiViewResult:
    T_world_view: np.ndarray          # (n, 4, 4)
    edges: tuple[EdgeResult, ...]     # last round's pairs
    sync: SyncResult                  # last synchronisation (edge residuals, inliers)
    rmse: float                       # RMS point-to-plane residual of the final poses, metres; lower is better

    def __repr__(self) -> str:
        acc = sum(e.accepted for e in self.edges)
        return f"MultiViewResult({len(self.T_world_view)} views, {acc}/{len(self.edges)} edges, rmse={self.rmse * 1e3:.3f} mm)"


def _prepare(clouds: Sequence[PointCloud], voxel: float) -> list[PointCloud]:
    out = []
    for k, c in enumerate(clouds):
        pts = np.asarray(c.points)
        if len(pts) < 50:
            raise RegistrationError(f"view {k}: {len(pts)} points; a scan needs at least 50 to register")
        if not np.all(np.isfinite(pts)):
            raise RegistrationError(f"view {k}: has NaN or infinite points; drop them first")
        p, n = voxel_downsample(pts, voxel, normals=c.normals)
        if n is None:
            n = estimate_normals(p, k=20)
        out.append(PointCloud(p, normals=n))
    return out


def pairwise_overlap(src: PointCloud, tgt_tree: cKDTree, T_tgt_src: np.ndarray, radius: float) -> float:
    """Fraction of ``src`` points that land within ``radius`` of the target after ``T_tgt_src``."""
    d, _ = tgt_tree.query(apply_T(T_tgt_src, src.points), k=1, distance_upper_bound=radius, workers=-1)
    return float(np.mean(np.isfinite(d)))


def _mutual_overlap(a: PointCloud, b: PointCloud, tree_a: cKDTree, tree_b: cKDTree, T_a_b: np.ndarray,
                    radius: float) -> float:
    """The larger of the two directed overlaps of views a and b (b's points in a, a's points in b)."""
    return max(pairwise_overlap(b, tree_a, T_a_b, radius), pairwise_overlap(a, tree_b, invert_T(T_a_b), radius))


def _sync(n: int, edges: list[EdgeResult]) -> SyncResult:
    acc = [(e.i, e.j, e.T_i_j) for e in edges if e.accepted]
    if not acc:
        raise RegistrationError("no pair of views was registered reliably; the scans may not overlap")
    return synchronise(n, acc, robust=True)


def _check_connected(n: int, edges: list[EdgeResult]) -> None:
    parent = list(range(n))

    def find(a):
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    for e in edges:
        if e.accepted:
            parent[find(e.i)] = find(e.j)
    groups: dict[int, list[int]] = {}
    for k in range(n):
        groups.setdefault(find(k), []).append(k)
    if len(groups) > 1:
        parts = sorted(groups.values(), key=len, reverse=True)
        raise RegistrationError(f"the scans do not all overlap: views {parts[1:]} have no reliable link to views "
                                f"{parts[0]}; scan more views in between or register those separately")


@dataclass(frozen=True, eq=False)
class JointResult:
    T_world_view: np.ndarray    # (n, 4, 4)
    rmse: float                 # weighted point-to-plane RMS over all pairs, metres
    n_iterations: int
    converged: bool
    pair_rmse: dict             # (i, j) -> RMS residual of that pair, metres


def refine_jointly(clouds: Sequence[PointCloud], T_world_view: np.ndarray, pairs: Sequence[tuple[int, int]], *,
                   max_distance: float, iterations: int = 15, samples: int = 8000, kernel_k: float = 1.345,
                   tolerance: float = 1e-9, rng: int = 0) -> JointResult:
    """Multi-view ICP: refine every pose at once (view 0 fixed) by Gauss-Newton on point-to-plane residuals
    of all overlapping ``pairs`` in both directions, re-associating closest points each iteration.

    The residual of a source point p (view j) and its closest target point q (view i, normal n), in world
    coordinates, is ``n . (T_j p - T_i q)``; small motions ``xi_k = (omega_k, v_k)`` of every pose about the
    scene centroid enter linearly, Huber weights use a MAD scale, and the 6(n-1) normal equations are solved
    densely. Unlike synchronising pairwise results, every correspondence weighs in directly.
    """
    n = len(clouds)
    T = np.array(T_world_view, dtype=np.float64, copy=True)
    gen = np.random.default_rng(rng)
    trees = [cKDTree(c.points) for c in clouds]
    subs = [c.points[gen.choice(len(c.points), min(samples, len(c.points)), replace=False)] for c in clouds]
    centre = np.mean([apply_T(T[k], c.points.mean(axis=0, keepdims=True))[0] for k, c in enumerate(clouds)], axis=0)
    directed = [(i, j) for i, j in pairs] + [(j, i) for i, j in pairs]
    converged, it, rmse, pair_rmse = False, 0, float("nan"), {}
    for it in range(1, iterations + 1):
        Hm = np.zeros((6 * n, 6 * n))
        g = np.zeros(6 * n)
        res_all, pair_rmse = [], {}
        for i, j in directed:  # target i, source j
            p_j = subs[j]
            T_i_j = invert_T(T[i]) @ T[j]
            d, idx = trees[i].query(apply_T(T_i_j, p_j), k=1, distance_upper_bound=max_distance, workers=-1)
            ok = np.isfinite(d)
            if np.count_nonzero(ok) < 10:
                continue
            Ri = T[i][:3, :3]
            pw = apply_T(T[j], p_j[ok]) - centre
            qw = apply_T(T[i], clouds[i].points[idx[ok]]) - centre
            nw = clouds[i].normals[idx[ok]] @ Ri.T
            r = np.einsum("ij,ij->i", pw - qw, nw)
            Jj = np.hstack([np.cross(pw, nw), nw])
            Ji = -np.hstack([np.cross(qw, nw), nw])
            res_all.append((i, j, r, Ji, Jj))
            pair_rmse[(min(i, j), max(i, j))] = float(np.sqrt(np.mean(r ** 2)))
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
        try:
            xi = -np.linalg.solve(A + 1e-12 * np.trace(A) / len(A) * np.eye(len(A)), g[free])
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


def register_views(clouds: Sequence[PointCloud], *, init_T_world_view: np.ndarray | None = None,
                   options: MultiViewOptions = MultiViewOptions(),
                   progress: Callable[[str], None] | None = None) -> MultiViewResult:
    """Register ``clouds`` (each in its own frame) into the first cloud's frame.

    Parameters
    ----------
    clouds : PointClouds in metres; normals are used when present (else estimated).
    init_T_world_view : (n, 4, 4), optional prior poses; None runs coarse alignment of every pair.
    options : MultiViewOptions.
    progress : called with one line per stage.
    """
    say = progress or (lambda msg: None)
    n = len(clouds)
    if n < 2:
        raise RegistrationError(f"multi-view registration needs at least 2 scans, found {n}")
    diag = bbox_diagonal(clouds)
    voxel = diag / 110.0 if options.voxel is None else check_voxel(options.voxel, diag, what="voxel")
    fine = voxel / 3.0 if options.fine_voxel is None else check_voxel(options.fine_voxel, diag, what="fine_voxel")
    coarse_clouds = _prepare(clouds, voxel)
    fine_clouds = _prepare(clouds, fine)

    if init_T_world_view is None:
        say(f"coarse alignment of {n * (n - 1) // 2} pairs (voxel {voxel * 1e3:.2f} mm)")
        copt = CoarseOptions(voxel=voxel, rng=options.rng)
        feats = [compute_features(c, copt) for c in coarse_clouds]
        edges = []
        for i in range(n):
            for j in range(i + 1, n):
                r = coarse_align(feats[j], feats[i], copt)
                ok = r.rmse < options.max_coarse_rmse * voxel and r.fitness >= options.min_overlap
                edges.append(EdgeResult(i, j, r.T_target_source, r.rmse, r.fitness, bool(ok)))
        _check_connected(n, edges)
        T = _sync(n, edges).T_world_view
    else:
        T = np.asarray(init_T_world_view, dtype=np.float64).copy()
        if T.shape != (n, 4, 4):
            raise RegistrationError(f"init_T_world_view must be ({n}, 4, 4), found {T.shape}")
        T = np.einsum("ij,njk->nik", invert_T(T[0]), T)  # world = first view

    edges: list[EdgeResult] = []
    sync = None
    for rnd in range(options.rounds):
        level = coarse_clouds if rnd == 0 else fine_clouds
        v = voxel if rnd == 0 else fine
        trees = [cKDTree(c.points) for c in level]
        # Wide gate on a coarser level first (the prior may be degrees off), then a 2-voxel gate, so the
        # final RMSE measures the overlap only and is comparable with the coarse stage's.
        icp_opt = replace(options.icp, max_distance=2.0 * v, voxel_sizes=(2.0 * v,), rng=options.rng + rnd)
        edges = []
        for i in range(n):
            for j in range(i + 1, n):
                T_i_j = invert_T(T[i]) @ T[j]
                ov = _mutual_overlap(level[i], level[j], trees[i], trees[j], T_i_j, 2 * v)
                if ov < options.min_overlap:
                    continue
                r = icp(level[j], level[i], init_T_target_source=T_i_j, options=icp_opt)
                ov = pairwise_overlap(level[j], trees[i], r.T_target_source, 2 * v)
                moved = np.degrees(rotation_angle(r.T_target_source[:3, :3] @ T_i_j[:3, :3].T))
                ok = r.rmse < options.max_rmse * v and ov >= options.min_overlap
                reason = "" if ok else (f"rmse {r.rmse * 1e3:.3f} mm > {options.max_rmse * v * 1e3:.3f}"
                                        if r.rmse >= options.max_rmse * v else f"overlap {ov:.2f}")
                edges.append(EdgeResult(i, j, r.T_target_source, r.rmse, ov, bool(ok),
                                        reason + (f" (moved {moved:.1f} deg)" if moved > 5 else "")))
        _check_connected(n, edges)
        sync = _sync(n, edges)
        T = sync.T_world_view
        acc = [e for e in edges if e.accepted]
        say(f"round {rnd + 1}: {len(acc)}/{len(edges)} overlapping pairs accepted, mean rmse "
            f"{np.mean([e.rmse for e in acc]) * 1e3:.3f} mm")
    acc = [e for e in edges if e.accepted]
    rmse = float(np.mean([e.rmse for e in acc]))
    if options.joint_iterations > 0:
        # Pairs by overlap at the synchronised poses (not by which pairwise runs passed), so the same data
        # gives the same problem whatever the starting poses were.
        trees = [cKDTree(c.points) for c in fine_clouds]
        pairs = []
        for i in range(n):
            for j in range(i + 1, n):
                ov = _mutual_overlap(fine_clouds[i], fine_clouds[j], trees[i], trees[j], invert_T(T[i]) @ T[j],
                                     2 * fine)
                if ov >= options.min_overlap:
                    pairs.append((i, j))
        joint = refine_jointly(fine_clouds, T, pairs, max_distance=2.5 * fine, iterations=options.joint_iterations,
                               samples=options.joint_samples, tolerance=options.joint_tolerance, rng=options.rng)
        T = joint.T_world_view
        rmse = joint.rmse
        say(f"joint refinement of {n} views over {len(pairs)} pairs: rmse {joint.rmse * 1e3:.4f} mm, "
            f"{joint.n_iterations} iterations{'' if joint.converged else ' (not converged)'}")
    return MultiViewResult(T, tuple(edges), sync, rmse)


def overlap_rms(clouds: Sequence[PointCloud], T_world_view: np.ndarray, *, radius: float = 0.001) -> float:
    """RMS distance between overlapping scans: for every ordered pair, each point of one scan to its
    nearest neighbour in the other if closer than ``radius`` (metres). A measure of how well poses fit
    the data (used to compare with a reference alignment such as Stanford's bun.conf)."""
    world = [apply_T(T, np.asarray(c.points)) for c, T in zip(clouds, T_world_view)]
    trees = [cKDTree(w) for w in world]
    sq, count = 0.0, 0
    for i in range(len(world)):
        for j in range(len(world)):
            if i == j:
                continue
            d, _ = trees[i].query(world[j], k=1, distance_upper_bound=radius, workers=-1)
            d = d[np.isfinite(d)]
            sq += float(np.sum(d ** 2))
            count += d.size
    return float(np.sqrt(sq / max(count, 1)))
