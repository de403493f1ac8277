"""A rig's second device refined from a capture's own correspondences (issue 47: "refines the rig from the capture").

Input: N correspondences, pixel ``uv_first[i]`` of the first device (a camera) and ``uv_second[i]`` of the second
(the projector's decoded (column, row), or a second camera's matched pixel). Each pair is two rays that meet at a
surface point when the rig is right (:mod:`rangekit.rig.capture_check` measures how far they miss).

Method: a bundle adjustment of the second device's pose relative to the first, by variable projection. The points
are not parameters: at every step each pair is triangulated in closed form (the midpoint of the two rays' closest
points, :func:`rangekit.rig.capture_check.closest_points`) and the residuals are that point's reprojection errors,
in pixels, in both devices (4N residuals; each device's lens distortion undone for its rays and applied for its
projections, :func:`rangekit.lens.undistort` and :func:`rangekit.lens.distort`). scipy's trust-region solver
(``least_squares``, ``trf``, a finite-difference Jacobian of 5 to 9 columns) minimises them under a soft-L1 loss of
scale :data:`LOSS_SCALE_PX`. Wrong decodes are also left out: a few coarse solves on :data:`COARSE` of the pairs,
each on those within :data:`INLIER_SIGMA` sigma of the fit before (the given rig's, first), then one on every pair
the last coarse fit kept.

Frames and units: the rig's world frame, metres; pixels ``(u, v) = (column, row)``. The first device is held fixed.
Correspondences cannot see scale, so the baseline (the distance between the optical centres) is held: the second
centre moves on the sphere about the first, and the pose has 5 degrees of freedom (a rotation in the world frame, 3,
and the baseline's direction, 2).

Intrinsics: two views fix 7 numbers (the fundamental matrix); with the first device calibrated and the baseline's
length held, the pose takes 5, which leaves room for about 2 more. ``free_intrinsics=True`` frees the second
device's focal length ``f`` (fx and fy scaled together: what a projector's zoom or focus changes); a tuple names
any of ``f``, ``fx``, ``fy``, ``cx``, ``cy`` instead. Its distortion is held. Four (fx, fy, cx, cy) are more than
two views fix: the covariance rule below refuses them, naming them.

Refused with :class:`rangekit.errors.CalibrationError`: fewer than :data:`MIN_POINTS` correspondences;
correspondences spanning less than :data:`MIN_SPREAD` of either image's width or height; and, the general rule, a
parameter whose standard deviation at the solution (``sigma^2 (J^T J)^-1``, sigma from the residuals) is over its
:data:`STD_LIMITS` (about a pixel's worth): the data leave it unfixed (a plane with the focal length freed is one
such case); and a refinement that ends no better than it started.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.errors import CalibrationError, InputError
from rangekit.geometry import make_T, rotation_angle, rotvec_to_R
from rangekit.lens import distort, undistort
from rangekit.rig.capture_check import closest_points, ray_misses
from rangekit._runtime.threads import one_blas_thread

__all__ = ["COARSE", "INTRINSICS", "LOSS_SCALE_PX", "MIN_POINTS", "MIN_SPREAD", "STD_LIMITS", "RigRefinement",
           "refine_extrinsics"]

#: Fewest correspondences a refinement accepts.
MIN_POINTS = 200
#: Least part of each image side (width, height) the central 90 % of the correspondences must span, per device.
MIN_SPREAD = 0.10
#: The robust loss's scale (soft L1), pixels: residuals beyond it count about linearly.
LOSS_SCALE_PX = 1.0
#: Coarse solves, each on the pairs the one before kept; a pair is kept within this many sigma of its fit.
ROUNDS, INLIER_SIGMA = 3, 4.0
#: Correspondences of the first, coarse solve (the fine one takes them all, from where it ended).
COARSE = 2000
#: The intrinsics of the second device that may be freed: ``f`` scales fx and fy together.
INTRINSICS = ("f", "fx", "fy", "cx", "cy")
#: Largest standard deviation accepted per parameter: rotation (degrees, about each world axis), the baseline's
#: direction (millimetres at the second centre, each way), intrinsics (pixels). 0.05 deg turns 1500 px by 1.3 px.
STD_LIMITS = {"rotation": 0.05, "baseline": 1.0, "f": 3.0, "fx": 3.0, "fy": 3.0, "cx": 3.0, "cy": 3.0}
_POSE = (("rotation about world x", "rotation", "deg"), ("rotation about world y", "rotation", "deg"),
         ("rotation about world z", "rotation", "deg"), ("baseline direction 1", "baseline", "mm"),
         ("baseline direction 2", "baseline", "mm"))
_K_ENTRY = {"fx": (0, 0), "fy": (1, 1), "cx": (0, 2), "cy": (1, 2)}


@dataclass(frozen=True)
class RigRefinement:
    """What :func:`refine_extrinsics` found (module doc).

    ``second``: the second device refined (pose, and the intrinsics in ``freed``). ``before_px``, ``after_px``: the
    median miss in the second device's pixels as :func:`rangekit.rig.capture_check.check_rig` measures it (the first
    ray's closest point to the second ray, projected into the second) over the correspondences sampled, with the
    given and the refined rig. ``n_points``: the correspondences the final solve used; ``n_rejected``: those it
    left out as wrong (over :data:`INLIER_SIGMA` sigma from the coarse fit). ``iterations``: the solver's function
    evaluations over all its solves (steps tried; its finite-difference Jacobians not counted). ``rotation_deg``,
    ``translation_mm``: how far the second device turned and its centre moved (the baseline length held)."""

    second: PinholeCamera
    before_px: float
    after_px: float
    n_points: int
    n_rejected: int
    iterations: int
    seconds: float
    rotation_deg: float
    translation_mm: float
    freed: tuple[str, ...] = ()

    def describe(self) -> str:
        """One line for people."""
        freed = f", its {', '.join(self.freed)} freed" if self.freed else ""
        return (f"rig refinement: {self.second.name} predicted to {self.before_px:.2f} -> {self.after_px:.2f} px "
                f"(median) over {self.n_points} correspondences ({self.n_rejected} rejected); it turned "
                f"{self.rotation_deg:.3f} deg and moved {self.translation_mm:.2f} mm (baseline length held){freed}; "
                f"{self.iterations} iterations, {self.seconds:.2f} s")


class _Model:
    """The second device as a function of the parameters ``x``: a rotation vector (3, radians, world frame), the
    baseline direction's change (2, radians) and the freed intrinsics' changes in units of the given fx."""

    def __init__(self, first: PinholeCamera, second: PinholeCamera, freed: tuple[str, ...]) -> None:
        self.second, self.freed = second, freed
        offset = second.center - first.center
        self.baseline = float(np.linalg.norm(offset))
        if not self.baseline > 0:
            raise CalibrationError("rig refinement: the two devices share one optical centre (baseline 0 mm): "
                                   "correspondences fix no depth")
        self.u0 = offset / self.baseline
        self.tangent = np.linalg.svd(self.u0[None, :])[2][1:]   # (2, 3) orthonormal, perpendicular to u0
        self.origin, self.f0 = first.center, float(second.K[0, 0])
        self.parameters = _POSE + tuple((name, name, "px") for name in freed)
        self.n = len(self.parameters)

    def pose(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(3, 3) rotation (device to world) and (3,) centre, metres."""
        u = self.u0 + x[3:5] @ self.tangent
        R = rotvec_to_R(x[:3]) @ self.second.T_world_cam[:3, :3]
        return R, self.origin + self.baseline * u / np.linalg.norm(u)

    def K(self, x: np.ndarray) -> np.ndarray:
        """(3, 3) intrinsics: ``f`` scales fx and fy by ``1 + x``, the others move by ``x * fx``."""
        K = self.second.K.copy()
        for name, dx in zip(self.freed, x[5:]):
            if name == "f":
                K[[0, 1], [0, 1]] *= 1 + dx
            else:
                K[_K_ENTRY[name]] += dx * self.f0
        return K

    def device(self, x: np.ndarray) -> PinholeCamera:
        s = self.second
        return PinholeCamera(self.K(x), s.width, s.height, s.dist, make_T(*self.pose(x)), s.name)

    def std(self, x_std: np.ndarray) -> dict[str, tuple[float, float, str]]:
        """Each parameter's standard deviation, its limit and unit (:data:`STD_LIMITS`), by name."""
        scale = [np.degrees(1.0)] * 3 + [self.baseline * 1e3] * 2 + [self.f0] * len(self.freed)
        return {name: (float(s * k), STD_LIMITS[kind], unit)
                for (name, kind, unit), s, k in zip(self.parameters, x_std, scale)}


def _unit_rays(xy: np.ndarray) -> np.ndarray:
    d = np.column_stack([xy, np.ones(len(xy))])
    return d / np.linalg.norm(d, axis=1, keepdims=True)


def _pixels(P_dev: np.ndarray, K: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """(N, 3) points in a device's frame -> (N, 2) distorted pixels (``PinholeCamera.project_cam``'s formula)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        xy = distort(np.ascontiguousarray(P_dev[:, :2] / P_dev[:, 2:3]), dist)
    return xy * K[[0, 1], [0, 1]] + K[[0, 1], [2, 2]]


def _residual_function(model: _Model, first: PinholeCamera, uv1: np.ndarray, uv2: np.ndarray):
    """The residuals of x: (4N,) reprojection errors, pixels, of each pair's midpoint in both devices."""
    R1, dist2 = first.T_world_cam[:3, :3], model.second.dist
    d1 = _unit_rays(first.pixels_to_normalized(uv1)) @ R1.T
    rays2 = None if model.freed else _unit_rays(model.second.pixels_to_normalized(uv2))

    def fun(x: np.ndarray) -> np.ndarray:
        R2, centre2 = model.pose(x)
        K2 = model.K(x)
        if rays2 is None:                                            # intrinsics freed: the rays move
            d2 = _unit_rays(undistort((uv2 - K2[[0, 1], [2, 2]]) / K2[[0, 1], [0, 1]], dist2)) @ R2.T
        else:
            d2 = rays2 @ R2.T
        s, t = closest_points(model.origin, d1, centre2, d2)
        w = centre2 - model.origin
        P = 0.5 * (s[:, None] * d1 + t[:, None] * d2 + w)           # the midpoint, from the first centre
        P1, P2 = P @ R1, (P - w) @ R2
        r = np.concatenate([(_pixels(P1, first.K, first.dist) - uv1).ravel(),
                            (_pixels(P2, K2, dist2) - uv2).ravel()])
        behind = np.repeat((P1[:, 2] <= 0) | (P2[:, 2] <= 0), 2)
        r[np.r_[behind, behind] | ~np.isfinite(r)] = 1e3             # a fixed large miss: no gradient
        return r

    return fun


def _checked(first: PinholeCamera, second: PinholeCamera, uv_first, uv_second, sample: int):
    """The finite correspondences, at most ``sample`` drawn evenly; refusals of too few or too gathered ones."""
    uv1, uv2 = (np.asarray(a, dtype=np.float64) for a in (uv_first, uv_second))
    if uv1.ndim != 2 or uv1.shape[1:] != (2,) or uv1.shape != uv2.shape:
        raise InputError(f"rig refinement: uv_first and uv_second must be (N, 2) arrays of one length, found "
                         f"shapes {uv1.shape} and {uv2.shape}")
    ok = np.all(np.isfinite(uv1), axis=1) & np.all(np.isfinite(uv2), axis=1)
    uv1, uv2 = uv1[ok], uv2[ok]
    if len(uv1) < MIN_POINTS:
        raise CalibrationError(f"rig refinement: too few correspondences: {len(uv1)} finite, at least "
                               f"{MIN_POINTS} needed")
    pick = _evenly(len(uv1), sample)
    uv1, uv2 = uv1[pick], uv2[pick]
    for device, uv in ((first, uv1), (second, uv2)):
        spread = np.ptp(np.percentile(uv, [5, 95], axis=0), axis=0) / np.array(device.size)
        if np.min(spread) < MIN_SPREAD:
            raise CalibrationError(
                f"rig refinement: degenerate spread: the correspondences cover {100 * spread[0]:.1f}% x "
                f"{100 * spread[1]:.1f}% of {device.name}'s image (central 90%), at least {100 * MIN_SPREAD:.0f}% "
                "of its width and of its height needed")
    return uv1, uv2


def _evenly(n: int, most: int) -> np.ndarray:
    return np.linspace(0, n - 1, min(int(most), n)).round().astype(np.int64)


def _unfixed(model: _Model, fit, n_points: int) -> dict[str, tuple[float, float, str]]:
    """The parameters whose standard deviation over ``n_points`` correspondences is over its limit (name: std,
    limit, unit), from the solve ``fit`` over some of them (deviations scale as one over the root of the count)."""
    per_pair = _per_pair(fit.fun)
    sigma2 = _sigma2(per_pair) * len(per_pair) / n_points
    _, sv, vt = np.linalg.svd(fit.jac, full_matrices=False)
    with np.errstate(divide="ignore"):
        std = np.sqrt(np.sum((vt / sv[:, None]) ** 2, axis=0) * sigma2)
    return {name: v for name, v in model.std(std).items() if not v[0] <= v[1]}


def _refuse(unfixed: dict[str, tuple[float, float, str]], freed: tuple[str, ...]) -> None:
    if unfixed:
        figures = "; ".join(f"{name} {std:.3g} {unit} (limit {limit:g})"
                            for name, (std, limit, unit) in unfixed.items())
        raise CalibrationError(f"rig refinement: the correspondences do not fix {', '.join(unfixed)}: standard "
                               f"deviation {figures}; spread them over an object with depth"
                               + (", or free fewer intrinsics" if freed else ""))


def _freed(free_intrinsics: bool | tuple[str, ...]) -> tuple[str, ...]:
    freed = ("f",) if free_intrinsics is True else tuple(free_intrinsics or ())
    if any(name not in INTRINSICS for name in freed) or len(set(freed)) != len(freed) or (
            "f" in freed and ("fx" in freed or "fy" in freed)):
        raise InputError(f"rig refinement: free_intrinsics must be True, False or distinct names of {INTRINSICS} "
                         f"(f is fx and fy together, not beside them), found {free_intrinsics!r}")
    return freed


def refine_extrinsics(first: PinholeCamera, second: PinholeCamera, uv_first: np.ndarray, uv_second: np.ndarray,
                      *, free_intrinsics: bool | tuple[str, ...] = False, sample: int = 20_000) -> RigRefinement:
    """``second``'s pose refined against ``first`` (held) from correspondences ``uv_first`` (N, 2) pixels of
    ``first`` and ``uv_second`` (N, 2) pixels of ``second``, at most ``sample`` of them drawn evenly; the baseline
    length is held. ``free_intrinsics``: True frees ``second``'s focal length, a tuple names intrinsics of
    :data:`INTRINSICS`. Raises CalibrationError on what the data cannot support (module doc)."""
    start = time.perf_counter()
    freed = _freed(free_intrinsics)
    uv1, uv2 = _checked(first, second, uv_first, uv_second, sample)
    model = _Model(first, second, freed)
    x, keep, iterations = _fit(model, first, uv1, uv2)
    refined = model.device(x)
    before, after = (_median_miss(first, device, uv1, uv2) for device in (second, refined))
    if not after < before:
        raise CalibrationError(f"rig refinement: ended no better than it started ({before:.3f} -> {after:.3f} px "
                               f"median over {len(uv1)} correspondences): the rig is left as it was")
    turn = refined.T_world_cam[:3, :3] @ second.T_world_cam[:3, :3].T
    return RigRefinement(second=refined, before_px=before, after_px=after, n_points=int(keep.sum()),
                         n_rejected=int(len(keep) - keep.sum()), iterations=iterations,
                         seconds=time.perf_counter() - start, rotation_deg=float(np.degrees(rotation_angle(turn))),
                         translation_mm=float(np.linalg.norm(refined.center - second.center) * 1e3), freed=freed)


def _fit(model: _Model, first: PinholeCamera, uv1: np.ndarray,
         uv2: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """The parameters, the pairs kept (N,) bool and the solver's function evaluations: :data:`ROUNDS` coarse solves
    on :data:`COARSE` pairs, each on those within :data:`INLIER_SIGMA` of the fit before (the given rig's first),
    then one on every pair kept. Refuses early what the coarse figures, scaled to every pair, cannot fix."""
    x, iterations = np.zeros(model.n), 0
    coarse, residuals = _evenly(len(uv1), COARSE), _residual_function(model, first, uv1, uv2)
    keep = _inliers(residuals(x))
    for _ in range(ROUNDS):
        fit = _solve(model, first, uv1[coarse[keep[coarse]]], uv2[coarse[keep[coarse]]], x, 100)
        x, iterations = fit.x, iterations + int(fit.nfev)
        _refuse(_unfixed(model, fit, len(uv1)), model.freed)
        keep = _inliers(residuals(x))
    if keep.sum() < MIN_POINTS:
        raise CalibrationError(f"rig refinement: too few correspondences agree: {int(keep.sum())} of {len(uv1)} "
                               f"within {INLIER_SIGMA:g} sigma of the coarse fit, at least {MIN_POINTS} needed")
    fit = _solve(model, first, uv1[keep], uv2[keep], x, 30)
    _refuse(_unfixed(model, fit, int(keep.sum())), model.freed)
    return fit.x, keep, iterations + int(fit.nfev)


def _solve(model: _Model, first: PinholeCamera, uv1: np.ndarray, uv2: np.ndarray, x: np.ndarray, most: int):
    from scipy.optimize import least_squares  # scipy.optimize takes a while to import

    with one_blas_thread():                                 # thin (4N, 5) products: a second thread only spins
        return least_squares(_residual_function(model, first, uv1, uv2), x, method="trf", loss="soft_l1",
                             f_scale=LOSS_SCALE_PX, x_scale="jac", max_nfev=most)


def _inliers(residuals: np.ndarray) -> np.ndarray:
    """(N,) the pairs whose 4 residuals are within :data:`INLIER_SIGMA` sigma (sigma: :func:`_sigma2`)."""
    per_pair = _per_pair(residuals)
    return per_pair <= INLIER_SIGMA ** 2 * max(_sigma2(per_pair), 1e-6)


def _per_pair(residuals: np.ndarray) -> np.ndarray:
    return np.sum(residuals.reshape(2, -1, 2) ** 2, axis=(0, 2))


def _sigma2(per_pair: np.ndarray) -> float:
    """Pixels^2: each pair's 4 residuals keep about 1 degree of freedom (3 go to its point), so their squared sum
    is sigma^2 chi2(1), whose median is 0.455; the median keeps wrong decodes out of sigma."""
    return float(np.median(per_pair)) / 0.455


def _median_miss(first: PinholeCamera, second: PinholeCamera, uv1: np.ndarray, uv2: np.ndarray) -> float:
    off_px, _, good = ray_misses(first, second, uv1, uv2)
    return float(np.median(off_px[good])) if good.any() else float("inf")
