"""Coarse alignment with no initial guess: FPFH features (Open3D) matched mutually, then a seeded,
vectorised RANSAC over 3-point hypotheses (deterministic for a seed, unlike Open3D's threaded RANSAC),
refined on its inliers and verified by ICP.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

import numpy as np
from scipy.spatial import cKDTree

from rangekit.errors import RegistrationError
from rangekit.geometry import apply_T, procrustes
from rangekit.surface.cloud import PointCloud, estimate_normals, voxel_downsample
from rangekit.registration.icp import IcpOptions, RegistrationResult, icp

__all__ = ["CoarseOptions", "Features", "compute_features", "coarse_align", "coarse_align_seeds", "SEEDS"]

#: RANSAC seeds tried, in turn, while the verified result is refused (options.rng, rng + 1, ...). With 1-2% of the
#: feature matches right (a shiny object's views 60 degrees apart: 12-17 of 2181), one seed's 20000 hypotheses
#: can miss, and the symmetric wrong fit (the object flipped, 178 degrees off) wins; the next seed finds it.
SEEDS = 3


@dataclass(frozen=True)
class CoarseOptions:
    """Feature and RANSAC settings; lengths are multiples of ``voxel`` (metres)."""

    voxel: float                       # downsampling voxel edge, metres (about 1/100 of the object size)
    normal_radius: float = 2.0         # x voxel
    feature_radius: float = 5.0        # x voxel
    inlier_distance: float = 1.5       # x voxel: a correspondence agrees with a hypothesis
    n_hypotheses: int = 20000
    edge_ratio: float = 0.9            # 3-point samples whose edge lengths differ more are skipped
    rng: int = 0


@dataclass(frozen=True, eq=False)
class Features:
    """A downsampled cloud with normals and its (N, 33) FPFH descriptors."""

    points: np.ndarray
    normals: np.ndarray
    fpfh: np.ndarray


def compute_features(cloud: PointCloud, options: CoarseOptions) -> Features:
    """Voxel-downsample ``cloud`` and compute normals (if missing) and FPFH descriptors."""
    import open3d as o3d

    v = options.voxel
    pts, nrm = voxel_downsample(cloud.points, v, normals=cloud.normals)
    if nrm is None:
        nrm = estimate_normals(pts, k=20)
    if len(pts) < 10:
        raise RegistrationError(f"coarse alignment: only {len(pts)} points after {v * 1e3:.2f} mm voxels; "
                                "use a smaller voxel")
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    pc.normals = o3d.utility.Vector3dVector(nrm)
    f = o3d.pipelines.registration.compute_fpfh_feature(
        pc, o3d.geometry.KDTreeSearchParamHybrid(radius=options.feature_radius * v, max_nn=100))
    return Features(pts, nrm, np.asarray(f.data).T.copy())


def _batched_kabsch(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """(H, 4, 4) rigid transforms mapping the 3-point sets A (H, 3, 3) onto B."""
    ca, cb = A.mean(axis=1, keepdims=True), B.mean(axis=1, keepdims=True)
    S = np.einsum("hki,hkj->hij", B - cb, A - ca)
    U, _, Vt = np.linalg.svd(S)
    d = np.sign(np.linalg.det(U @ Vt))
    D = np.ones((len(A), 3))
    D[:, 2] = d
    R = U @ (D[:, :, None] * Vt)
    T = np.tile(np.eye(4), (len(A), 1, 1))
    T[:, :3, :3] = R
    T[:, :3, 3] = cb[:, 0] - np.einsum("hij,hj->hi", R, ca[:, 0])
    return T


def coarse_align(source: PointCloud | Features, target: PointCloud | Features, options: CoarseOptions, *,
                 verify: IcpOptions | None = None) -> RegistrationResult:
    """Estimate ``T_target_source`` with no initial guess.

    Returns the ICP-verified result (``verify``, default point-to-plane with max distance 2 voxels) whose
    ``reason`` also states the RANSAC inlier count. Deterministic for ``options.rng``.
    """
    fs = source if isinstance(source, Features) else compute_features(source, options)
    ft = target if isinstance(target, Features) else compute_features(target, options)
    # Mutual nearest neighbours in feature space.
    tree_t = cKDTree(ft.fpfh)
    _, s2t = tree_t.query(fs.fpfh, k=1, workers=1)
    _, t2s = cKDTree(fs.fpfh).query(ft.fpfh, k=1, workers=1)
    mutual = t2s[s2t] == np.arange(len(fs.points))
    src_idx = np.flatnonzero(mutual)
    if len(src_idx) < 3:
        raise RegistrationError(f"coarse alignment: only {len(src_idx)} mutual feature matches; the clouds may "
                                "not overlap, or the voxel is too large")
    ps, pt = fs.points[src_idx], ft.points[s2t[src_idx]]
    rng = np.random.default_rng(options.rng)
    H = options.n_hypotheses
    samples = rng.integers(0, len(ps), size=(H, 3))
    A, B = ps[samples], pt[samples]
    # Edge-length consistency (rigid motions keep distances).
    ea = np.linalg.norm(A[:, [0, 1, 2]] - A[:, [1, 2, 0]], axis=2)
    eb = np.linalg.norm(B[:, [0, 1, 2]] - B[:, [1, 2, 0]], axis=2)
    ok = np.all((np.minimum(ea, eb) >= options.edge_ratio * np.maximum(ea, eb)) & (ea > options.voxel), axis=1)
    if not np.any(ok):
        raise RegistrationError("coarse alignment: no consistent 3-point sample among the feature matches")
    T = _batched_kabsch(A[ok], B[ok])
    thr2 = (options.inlier_distance * options.voxel) ** 2
    best, best_count = None, -1
    for chunk in range(0, len(T), 2000):  # count inliers of 2000 hypotheses at a time
        Tc = T[chunk: chunk + 2000]
        moved = np.einsum("hij,kj->hki", Tc[:, :3, :3], ps) + Tc[:, None, :3, 3]
        counts = np.sum(np.sum((moved - pt) ** 2, axis=2) < thr2, axis=1)
        i = int(np.argmax(counts))
        if counts[i] > best_count:
            best, best_count = Tc[i], int(counts[i])
    inl = np.sum((apply_T(best, ps) - pt) ** 2, axis=1) < thr2
    if inl.sum() >= 3:
        best = procrustes(ps[inl], pt[inl]).T_dst_src
    verify = verify or IcpOptions(max_distance=2 * options.voxel, kernel="huber")
    res = icp(PointCloud(fs.points, normals=fs.normals), PointCloud(ft.points, normals=ft.normals),
              init_T_target_source=best, options=verify)
    return RegistrationResult(res.T_target_source, res.rmse, res.fitness, res.n_iterations, res.converged,
                              f"ransac: {best_count} of {len(ps)} feature matches; icp: {res.reason}",
                              res.residuals, res.constraint)


def coarse_align_seeds(source: Features, target: Features, options: CoarseOptions,
                       accept: Callable[[RegistrationResult], bool], seeds: int = SEEDS) -> RegistrationResult:
    """:func:`coarse_align` with seeds ``options.rng``, ``+1``, ... until ``accept`` holds for the verified result
    (at most ``seeds``): that result, or the one of largest fitness among the accepted-or-not when none holds
    (accepted first). Raises the first seed's :class:`RegistrationError` when no seed finds a fit at all.
    The first seed's result is returned as before whenever it is accepted."""
    best, first_error = None, None
    for seed in range(seeds):
        try:
            r = coarse_align(source, target, replace(options, rng=options.rng + seed))
        except RegistrationError as exc:
            first_error = first_error or exc
            continue
        ok = bool(accept(r))
        if best is None or (ok, r.fitness) > (best[0], best[1].fitness):
            best = (ok, r)
        if ok:
            break
    if best is None:
        raise first_error
    return best[1]
