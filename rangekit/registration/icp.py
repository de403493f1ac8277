"""Iterative closest point (Fusiello ch. 15): point-to-point, point-to-plane and symmetric objectives,
robust kernels with a MAD scale, trimming, a coarse-to-fine voxel schedule, and two associations:
a KD-tree for any cloud, or projection into an organised target scan (no tree at all).

The result maps the source into the target frame: ``p_target = T_target_source @ p_source``.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
from scipy.spatial import cKDTree

from rangekit._runtime.arguments import check_choice, check_instance, check_items, check_number, check_pose
from rangekit.camera import PinholeCamera
from rangekit.errors import InputError, RegistrationError
from rangekit.geometry import apply_T, make_T, procrustes, rotation_angle, rotvec_to_R, transform_vectors
from rangekit.surface.cloud import PointCloud, voxel_downsample
from rangekit.surface.convert import as_cloud
from rangekit.registration.stability import HeldMotions, PoseConstraint, held_step, pose_constraint

__all__ = ["IcpOptions", "RegistrationResult", "icp", "KERNELS", "MIN_NORMAL_COS", "OrganisedScan"]

KERNELS = ("none", "huber", "cauchy", "tukey", "geman_mcclure", "welsch")
METHODS = ("point_to_point", "point_to_plane", "symmetric")
#: A correspondence counts only when its two normals are within 60 degrees (when both clouds have
#: normals): the front and back faces of a thin part (a 1-2 mm fin) lie within the distance gate.
MIN_NORMAL_COS = 0.5


@dataclass(frozen=True)
class IcpOptions:
    """ICP settings (distances in metres)."""

    method: str = "point_to_plane"      # "point_to_point", "point_to_plane" or "symmetric"
    max_distance: float = 0.005         # correspondences farther apart are ignored
    max_iterations: int = 50
    kernel: str = "huber"               # robust kernel, see KERNELS
    kernel_scale: float | None = None   # metres; None: 1.4826 * MAD of the residuals, each iteration
    trim: float = 0.0                   # fraction of the worst correspondences dropped each iteration
    voxel_sizes: tuple[float, ...] = ()  # coarse-to-fine schedule: ICP on voxel-downsampled clouds first
    max_samples: int | None = 10000     # source points used (one random subset per level, seeded) and
                                        # for the final statistics; None: all
    tolerance: float = 1e-9             # stop when the update moves points by less (metres, at the cloud's size)
    rng: int = 0

    def __post_init__(self) -> None:
        check_choice("method", self.method, METHODS)
        check_choice("kernel", self.kernel, KERNELS)
        check_number("max_distance", self.max_distance, lo=0, lo_open=True, unit="metres")
        check_number("max_iterations", self.max_iterations, lo=1, integer=True)
        check_number("kernel_scale", self.kernel_scale, lo=0, lo_open=True, unit="metres", optional=True)
        check_number("trim", self.trim, lo=0, hi=1, hi_open=True)
        for k, voxel in enumerate(check_items("voxel_sizes", self.voxel_sizes, "a tuple of voxel sizes (metres)")):
            check_number(f"voxel_sizes[{k}]", voxel, lo=0, unit="metres")
        check_number("max_samples", self.max_samples, lo=1, integer=True, optional=True)
        check_number("tolerance", self.tolerance, lo=0, unit="metres")
        check_number("rng", self.rng, lo=0, integer=True)


@dataclass(frozen=True, eq=False)
class RegistrationResult:
    """Result of a pairwise registration."""

    T_target_source: np.ndarray  # (4, 4) float64; p_target = T_target_source @ p_source
    rmse: float                  # inlier RMS distance in metres (point-to-plane: along the normal); lower is better
    fitness: float               # source points with a correspondence within max_distance / all; higher is better
    n_iterations: int
    converged: bool
    reason: str = ""             # why it stopped
    residuals: np.ndarray = field(default_factory=lambda: np.zeros(0))  # (K,) final inlier residuals, metres
    constraint: PoseConstraint | None = None  # which motions the final inliers fix (rangekit.registration.
                                              # stability); None without target normals

    def __repr__(self) -> str:
        ang = np.degrees(rotation_angle(self.T_target_source[:3, :3]))
        return (f"RegistrationResult(angle={ang:.4f} deg, t={np.round(self.T_target_source[:3, 3], 5).tolist()}, "
                f"rmse={self.rmse * 1e3:.4f} mm, fitness={self.fitness:.3f}, iterations={self.n_iterations}, "
                f"converged={self.converged}, reason={self.reason!r})")


@dataclass(frozen=True, eq=False)
class OrganisedScan:
    """A target scan kept as its range map, for projective association.

    ``xyz`` (H, W, 3) points in the TARGET frame (NaN where invalid), ``normals`` the same shape, and the
    ``camera`` that took it with ``T_world_cam`` expressed in that frame (for a scan in its own camera
    frame: identity).
    """

    xyz: np.ndarray
    normals: np.ndarray
    camera: PinholeCamera

    def cloud(self) -> PointCloud:
        ok = np.isfinite(self.xyz[:, :, 0]) & np.isfinite(self.normals[:, :, 0])
        return PointCloud(self.xyz[ok], normals=self.normals[ok])


# --------------------------------------------------------------------------- helpers
def _as_cloud(x, name: str) -> PointCloud:
    cloud = as_cloud(x, f"icp {name}")
    ok = np.all(np.isfinite(cloud.points), axis=1)
    if not np.all(ok):
        cloud = PointCloud(cloud.points[ok], None if cloud.colours is None else cloud.colours[ok],
                           None if cloud.normals is None else cloud.normals[ok])
    if len(cloud) < 3:
        raise RegistrationError(f"ICP {name}: needs at least 3 finite points, found {len(cloud)}")
    return cloud


def _weights(r: np.ndarray, kernel: str, scale: float) -> np.ndarray:
    """IRLS weights w = rho'(r) / r for residuals r (any sign)."""
    a = np.abs(r) / max(scale, 1e-15)
    if kernel == "none":
        return np.ones_like(a)
    if kernel == "huber":
        return np.where(a <= 1.345, 1.0, 1.345 / np.maximum(a, 1e-15))
    if kernel == "cauchy":
        return 1.0 / (1.0 + (a / 2.3849) ** 2)
    if kernel == "tukey":
        return np.where(a < 4.6851, (1 - (a / 4.6851) ** 2) ** 2, 0.0)
    if kernel == "geman_mcclure":
        return 1.0 / (1.0 + a ** 2) ** 2
    return np.exp(-((a / 2.9846) ** 2))  # welsch


# --------------------------------------------------------------------------- associations
class _KdAssociation:
    def __init__(self, target: PointCloud) -> None:
        self.points = target.points
        self.normals = target.normals
        self.tree = cKDTree(target.points, leafsize=16, balanced_tree=False, compact_nodes=False)

    def __call__(self, p: np.ndarray, max_distance: float):
        d, idx = self.tree.query(p, k=1, distance_upper_bound=max_distance, workers=1)
        ok = np.isfinite(d)
        idx = np.where(ok, idx, 0)
        return ok, self.points[idx], None if self.normals is None else self.normals[idx]


class _ProjectiveAssociation:
    def __init__(self, scan: OrganisedScan) -> None:
        self.scan = scan
        self.camera = scan.camera

    def __call__(self, p: np.ndarray, max_distance: float):
        """Bilinear interpolation of the range map at the projection (nearest pixel where a neighbour is
        missing), so correspondences are not quantised to the pixel grid."""
        uv = self.camera.project(p)
        H, W = self.scan.xyz.shape[:2]
        inside = np.isfinite(uv[:, 0]) & (uv[:, 0] >= 0) & (uv[:, 0] <= W - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= H - 1)
        uu = np.where(inside, uv[:, 0], 0.0)
        vv = np.where(inside, uv[:, 1], 0.0)
        u0 = np.minimum(np.floor(uu).astype(np.int64), W - 2)
        v0 = np.minimum(np.floor(vv).astype(np.int64), H - 2)
        fu, fv = (uu - u0)[:, None], (vv - v0)[:, None]
        X, N = self.scan.xyz, self.scan.normals
        corners = [(v0, u0, (1 - fu) * (1 - fv)), (v0, u0 + 1, fu * (1 - fv)), (v0 + 1, u0, (1 - fu) * fv),
                   (v0 + 1, u0 + 1, fu * fv)]
        q = sum(X[a, b] * w for a, b, w in corners)
        n = sum(N[a, b] * w for a, b, w in corners)
        near = ~np.isfinite(q[:, 0]) | ~np.isfinite(n[:, 0])
        if np.any(near):
            ui = np.rint(uu[near]).astype(np.int64)
            vi = np.rint(vv[near]).astype(np.int64)
            q[near], n[near] = X[vi, ui], N[vi, ui]
        with np.errstate(invalid="ignore"):
            n /= np.linalg.norm(n, axis=1, keepdims=True)
        ok = inside & np.isfinite(q[:, 0]) & np.isfinite(n[:, 0])
        ok &= np.sum((np.where(ok[:, None], q, 0) - p) ** 2, axis=1) <= max_distance ** 2
        return ok, q, n


# --------------------------------------------------------------------------- one level of ICP
def _solve_increment(method: str, p: np.ndarray, q: np.ndarray, nq: np.ndarray | None, np_: np.ndarray | None,
                     w: np.ndarray, hold: HeldMotions | None = None) -> np.ndarray | None:
    """(4, 4) increment applied to the (already transformed) source points, or None when the weighted
    system is singular (e.g. every weight is 0), so there is no increment to take. ``hold``: motions the
    increment must not have (point-to-plane and symmetric; :func:`rangekit.registration.stability.held_step`)."""
    if method == "point_to_point":
        if np.count_nonzero(w > 0) < 3:
            return None
        return procrustes(p, q, weights=w).T_dst_src
    if method == "point_to_plane":
        n = nq
        r = np.einsum("ij,ij->i", p - q, n)
        J = np.hstack([np.cross(p, n), n])
    else:  # symmetric (Rusinkiewicz 2019): normals of both sides, rotation split between them
        n = nq + np_
        n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
        r = np.einsum("ij,ij->i", p - q, n)
        J = np.hstack([np.cross(p + q, n), n])
    if hold is not None and len(hold.motions):
        if not np.any(w > 0):
            return None
        x = held_step(J, r, w, p if method == "point_to_plane" else p + q, 1 if method == "point_to_plane" else 2,
                      hold)
        if x is None:
            return None
    else:
        A = J.T @ (J * w[:, None])
        b = -J.T @ (w * r)
        try:
            x = np.linalg.solve(A + 1e-12 * np.trace(A) / 6 * np.eye(6), b)
        except np.linalg.LinAlgError:
            return None
        if not np.all(np.isfinite(x)):
            return None
    if method == "point_to_plane":
        return make_T(rotvec_to_R(x[:3]), x[3:])
    # symmetric: rotate by theta = atan(|a|) about a, translate t cos(theta), rotate again (R T R)
    a, t = x[:3], x[3:]
    na = np.linalg.norm(a)
    theta = np.arctan(na)
    R = rotvec_to_R(a / na * theta) if na > 0 else np.eye(3)
    Rm = make_T(R)
    return Rm @ make_T(None, t * np.cos(theta)) @ Rm


def _icp_level(src: PointCloud, assoc, T: np.ndarray, opt: IcpOptions, rng: np.random.Generator, size: float,
               hold: HeldMotions | None = None):
    P_all = src.points
    N_all = src.normals
    n_iter, reason, converged = 0, f"max_iterations={opt.max_iterations}", False
    need_src_normals = opt.method == "symmetric"
    if hold is not None and opt.method == "point_to_point":
        raise InputError("icp: hold needs method='point_to_plane' or 'symmetric'")
    if need_src_normals and N_all is None:
        raise RegistrationError("symmetric ICP needs source normals; give PointCloud(points, normals=...)")
    # One random subset per level: the same points every iteration, so the updates settle and stop.
    if opt.max_samples is not None and len(P_all) > opt.max_samples:
        sel = np.sort(rng.choice(len(P_all), opt.max_samples, replace=False))
    else:
        sel = slice(None)
    for n_iter in range(1, opt.max_iterations + 1):
        p = apply_T(T, P_all[sel])
        ok, q, nq = assoc(p, opt.max_distance)
        if np.count_nonzero(ok) < 6:
            return T, n_iter, False, f"degenerate: {np.count_nonzero(ok)} correspondences within {opt.max_distance} m"
        if nq is not None and N_all is not None:
            # Only surfaces facing the same way: the two faces of a thin part are closer than the gate.
            facing = np.einsum("ij,ij->i", transform_vectors(T, N_all[sel][ok]), nq[ok]) > MIN_NORMAL_COS
            ok = ok.copy()
            ok[np.flatnonzero(ok)[~facing]] = False
            if np.count_nonzero(ok) < 6:
                return T, n_iter, False, (f"degenerate: {np.count_nonzero(ok)} correspondences within "
                                          f"{opt.max_distance} m with normals within 60 deg")
        p, q = p[ok], q[ok]
        nq = None if nq is None else nq[ok]
        np_ = transform_vectors(T, N_all[sel][ok]) if need_src_normals else None
        if opt.method != "point_to_point" and nq is None:
            raise RegistrationError(f"{opt.method} ICP needs target normals; give the target PointCloud normals")
        if opt.method == "point_to_point":
            r = np.linalg.norm(p - q, axis=1)
        else:
            n_r = nq if opt.method == "point_to_plane" else (nq + np_)
            r = np.einsum("ij,ij->i", p - q, n_r / np.maximum(np.linalg.norm(n_r, axis=1, keepdims=True), 1e-12))
        keep = np.ones(len(r), bool)
        if opt.trim > 0:
            keep = np.abs(r) <= np.quantile(np.abs(r), 1 - opt.trim)
        scale = opt.kernel_scale if opt.kernel_scale is not None else \
            max(1.4826 * np.median(np.abs(r[keep] - (np.median(r[keep]) if opt.method != "point_to_point" else 0))),
                1e-9)
        w = _weights(r, opt.kernel, scale) * keep
        dT = _solve_increment(opt.method, p, q, nq, np_, w, hold)
        if dT is None:
            return T, n_iter, False, (f"singular system at iteration {n_iter}: {np.count_nonzero(w > 0)} of "
                                      f"{len(w)} correspondences have weight > 0 ({opt.kernel} kernel, scale "
                                      f"{scale:.3g} m); they do not constrain the pose")
        T = dT @ T
        step = np.linalg.norm(dT[:3, 3]) + rotation_angle(dT[:3, :3]) * size
        if step < opt.tolerance:
            converged, reason = True, f"update < {opt.tolerance:g} m"
            break
    return T, n_iter, converged, reason


def icp(source, target, *, init_T_target_source: np.ndarray | None = None, options: IcpOptions = IcpOptions(),
        target_scan: OrganisedScan | None = None, hold: HeldMotions | None = None) -> RegistrationResult:
    """Align ``source`` to ``target``.

    Parameters
    ----------
    source, target : PointCloud, (N, 3) array (metres) or any cloud :func:`rangekit.surface.convert.as_cloud`
        takes (Open3D, trimesh). Point-to-plane needs target normals, symmetric
        needs both clouds' normals.
    init_T_target_source : (4, 4) initial guess (default identity).
    options : IcpOptions.
    target_scan : OrganisedScan, optional. If given, correspondences come from projecting the source into
        the target's range map (projective association, no KD-tree); ``target`` may then be None.
    hold : HeldMotions, optional (target frame). The pose is not updated along these motions: the initial
        guess is kept along them (e.g. the motions a symmetric surface leaves free; see
        :mod:`rangekit.registration.stability`).

    Returns
    -------
    RegistrationResult. A run that ends with too few correspondences returns ``converged=False`` with a
    reason, not an exception; empty inputs raise RegistrationError.
    """
    check_instance("options", options, IcpOptions, "an IcpOptions")
    check_instance("target_scan", target_scan, OrganisedScan, "an OrganisedScan", optional=True)
    check_instance("hold", hold, HeldMotions, "a HeldMotions", optional=True)
    init = check_pose("init_T_target_source", init_T_target_source, optional=True)
    src = _as_cloud(source, "source")
    if target_scan is not None:
        tgt = target_scan.cloud()
    else:
        if target is None:
            raise InputError("icp: give a target cloud or a target_scan")
        tgt = _as_cloud(target, "target")
    if options.method != "point_to_point" and tgt.normals is None:
        raise RegistrationError(f"{options.method} ICP needs target normals; give the target PointCloud normals "
                                "(rangekit.surface.cloud.estimate_normals) or use method='point_to_point'")
    if options.method == "symmetric" and src.normals is None:
        raise RegistrationError("symmetric ICP needs source normals too; give PointCloud(points, normals=...)")
    T = np.eye(4) if init is None else init.copy()
    size = float(np.linalg.norm(np.ptp(tgt.points, axis=0)))
    rng = np.random.default_rng(options.rng)
    total = 0
    converged, reason = False, ""
    levels = list(options.voxel_sizes) + [0.0]
    for voxel in levels:
        if voxel > 0:
            sp, sn = voxel_downsample(src.points, voxel, normals=src.normals)
            s = PointCloud(sp, normals=sn)
            tp, tn = voxel_downsample(tgt.points, voxel, normals=tgt.normals)
            t_level = PointCloud(tp, normals=tn)
            assoc = _KdAssociation(t_level)
            opt = replace(options, max_distance=max(options.max_distance, 3 * voxel))
        else:
            s = src
            assoc = _ProjectiveAssociation(target_scan) if target_scan is not None else _KdAssociation(tgt)
            opt = options
        T, n, converged, reason = _icp_level(s, assoc, T, opt, rng, size, hold)
        total += n
    # Final statistics (on max_samples random source points: fitness and RMSE are estimates then).
    P = src.points
    if options.max_samples is not None and len(P) > options.max_samples:
        P = P[rng.choice(len(P), options.max_samples, replace=False)]
    p = apply_T(T, P)
    ok, q, nq = assoc(p, options.max_distance)
    if options.method == "point_to_plane" and nq is not None:
        res = np.abs(np.einsum("ij,ij->i", p[ok] - q[ok], nq[ok]))
    else:
        res = np.linalg.norm(p[ok] - q[ok], axis=1)
    rmse = float(np.sqrt(np.mean(res ** 2))) if res.size else float("inf")
    constraint = None
    if nq is not None and np.count_nonzero(ok) >= 6:
        constraint = pose_constraint(q[ok], nq[ok])
    return RegistrationResult(T, rmse, float(np.count_nonzero(ok) / len(P)), total, converged, reason, res,
                              constraint)
