"""Projector calibration: projector coordinates of board corners, then camera + projector by bundle adjustment.

Projector coordinates of a corner
---------------------------------
Coded light gives every camera pixel the projector column and row it sees (with a confidence). A board
corner found at subpixel camera position (u0, v0) needs the projector coordinates at exactly that point.
Our estimator (designed here; it is not the local-homography method of Moreno and Taubin) is a robust,
confidence-weighted local quadratic regression, one per corner and per projector axis:

    proj(u0 + du, v0 + dv) ~ c0 + c1 du + c2 dv + c3 du^2 + c4 du dv + c5 dv^2

over the camera pixels of a (2r + 1)^2 window around the corner, and the estimate is c0, the fitted value at
the corner itself. Each pixel's weight is the decoder's confidence (modulation over full scale: the dark
squares count less), times a Gaussian taper (sigma = r / 1.5 px) that favours pixels near the corner, times
Tukey's biweight of its residual (iteratively reweighted, 4 rounds; scale = 1.4826 x the weighted median
absolute residual, floored at 0.02 projector px), which removes pixels the decoder got wrong. A quadratic
follows the perspective and lens curvature of the projector coordinates across the window, and because the
window is centred on the corner, the blur of the checker edges, which pulls dark pixels towards their
bright neighbours' codes, acts point-symmetrically about the corner and cancels in c0. All corners are
solved at once: (n, 6, 6) weighted normal equations. A corner is dropped (NaN) when fewer than
``min_pixels`` pixels carry weight (the corner is outside the projector's image or in shadow).

Bundle adjustment
-----------------
:func:`bundle_adjust` refines the camera's and the projector's intrinsics and distortion, the projector's
pose relative to the camera and every board pose together, minimising the reprojection error of the board
corners in both devices (each scaled by its own noise level) with ``scipy.optimize.least_squares`` and a
sparse Jacobian (a board pose touches only its own view's residuals). A lens model with fewer parameters
(k1 alone, a fixed aspect ratio or principal point: :data:`rangekit.calib.camera.LENS_MODELS`) holds the
others at their initial values (``fixed_camera``, ``fixed_projector``).

Frames: world = the camera's frame; the projector's pose is ``T_cam_proj``; board poses ``T_cam_board``.
"""

from __future__ import annotations

from dataclasses import dataclass
import numpy as np
from scipy.optimize import least_squares

from rangekit.calib.bundle.problem import BundleProblem, make_bundle_problem
from rangekit.camera import PinholeCamera
from rangekit.errors import CalibrationError
from rangekit.geometry import invert_T, make_T, nearest_rotation, rotvec_to_R

__all__ = ["CornerFit", "corner_projector_coords", "BundleResult", "bundle_adjust", "initial_T_proj_cam"]


@dataclass(frozen=True)
class CornerFit:
    """Projector coordinates of board corners: ``proj_uv`` (n, 2) px (NaN rows where not estimated),
    ``std`` (n, 2) px standard error of each estimate from the fit's residuals, ``n_pixels`` (n,) pixels
    that carried weight."""

    proj_uv: np.ndarray
    std: np.ndarray
    n_pixels: np.ndarray

    @property
    def ok(self) -> np.ndarray:
        return np.all(np.isfinite(self.proj_uv), axis=1)


def corner_projector_coords(proj_col: np.ndarray, proj_row: np.ndarray, confidence: np.ndarray,
                            uv: np.ndarray, *, radius: int = 8, min_pixels: int = 40,
                            iterations: int = 4) -> CornerFit:
    """Projector coordinates at subpixel camera points by robust local quadratic regression (module doc).

    Parameters
    ----------
    proj_col, proj_row : (H, W) float decoded projector column and row per camera pixel, NaN where invalid.
    confidence : (H, W) float in [0, 1], the decoder's confidence (0 where invalid).
    uv : (n, 2) camera pixel positions of the corners (pixel centres at integers).
    radius : half-size of the window in camera pixels.
    min_pixels : minimum number of weighted pixels for an estimate.
    iterations : rounds of robust reweighting.
    """
    uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
    H, W = proj_col.shape
    n = len(uv)
    r = int(radius)
    off = np.arange(-r, r + 1)
    oy, ox = np.meshgrid(off, off, indexing="ij")
    ox, oy = ox.ravel(), oy.ravel()                               # (P,)
    cx = np.rint(uv[:, 0]).astype(np.int64)
    cy = np.rint(uv[:, 1]).astype(np.int64)
    px = cx[:, None] + ox[None]                                    # (n, P)
    py = cy[:, None] + oy[None]
    inside = (px >= 0) & (px < W) & (py >= 0) & (py < H)
    pxc, pyc = np.clip(px, 0, W - 1), np.clip(py, 0, H - 1)
    col = proj_col[pyc, pxc].astype(np.float64)
    row = proj_row[pyc, pxc].astype(np.float64)
    conf = confidence[pyc, pxc].astype(np.float64)
    valid = inside & np.isfinite(col) & np.isfinite(row) & (conf > 0)
    du = px - uv[:, 0:1]
    dv = py - uv[:, 1:2]
    A = np.stack([np.ones_like(du), du, dv, du * du, du * dv, dv * dv], axis=2)   # (n, P, 6)
    sigma_taper = r / 1.5
    w0 = np.where(valid, conf * np.exp(-(du * du + dv * dv) / (2 * sigma_taper ** 2)), 0.0)
    Y = np.stack([np.where(valid, col, 0.0), np.where(valid, row, 0.0)], axis=2)     # (n, P, 2)
    w = w0.copy()
    coef = np.zeros((n, 6, 2))
    for it in range(iterations + 1):
        AtW = A * w[:, :, None]
        N = np.einsum("npi,npj->nij", AtW, A) + 1e-9 * np.eye(6)
        b = np.einsum("npi,npk->nik", AtW, Y)
        coef = np.linalg.solve(N, b)                                # (n, 6, 2)
        if it == iterations:
            break
        res = Y - np.einsum("npi,nik->npk", A, coef)
        e = np.hypot(res[..., 0], res[..., 1])
        scale = np.maximum(1.4826 * _weighted_median(np.where(w0 > 0, e, np.nan), w0), 0.02)
        c = 4.685 * scale[:, None]
        w = w0 * np.where(e < c, (1 - (e / c) ** 2) ** 2, 0.0)
    res = Y - np.einsum("npi,nik->npk", A, coef)
    used = w > 1e-3 * np.maximum(w.max(axis=1, keepdims=True), 1e-300)
    n_used = used.sum(axis=1)
    # Standard error of c0 (sandwich estimate with the weights as given): sigma^2 (A'WA)^-1 A'W^2A (A'WA)^-1.
    AtW = A * w[:, :, None]
    N = np.einsum("npi,npj->nij", AtW, A) + 1e-9 * np.eye(6)
    Ninv = np.linalg.inv(N)
    M = np.einsum("npi,npj->nij", AtW, AtW)
    cov00 = np.einsum("ni,nij,nj->n", Ninv[:, 0, :], M, Ninv[:, 0, :])
    dof = np.maximum(n_used - 6, 1)
    s2 = np.einsum("np,npk->nk", used.astype(float), res ** 2) / dof[:, None]
    std = np.sqrt(np.maximum(cov00[:, None] * s2, 0.0))
    est = coef[:, 0, :].copy()
    bad = n_used < min_pixels
    est[bad] = np.nan
    std[bad] = np.nan
    return CornerFit(proj_uv=est, std=std, n_pixels=n_used)


def _weighted_median(values: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Row-wise weighted median of ``values`` (n, P), ignoring NaN; NaN rows -> 0."""
    v = np.where(np.isfinite(values), values, np.inf)
    order = np.argsort(v, axis=1)
    vs = np.take_along_axis(v, order, axis=1)
    ws = np.take_along_axis(np.where(np.isfinite(values), weights, 0.0), order, axis=1)
    cw = np.cumsum(ws, axis=1)
    half = 0.5 * cw[:, -1:]
    k = np.argmax(cw >= half, axis=1)
    out = vs[np.arange(len(v)), k]
    return np.where(np.isfinite(out), out, 0.0)


# --------------------------------------------------------------------------- bundle adjustment
def initial_T_proj_cam(T_cam_board: dict, T_proj_board: dict) -> np.ndarray:
    """``T_proj_cam`` from board poses seen by both devices: chordal mean of the rotations, median translation."""
    common = sorted(set(T_cam_board) & set(T_proj_board))
    if not common:
        raise CalibrationError("projector: no view has the board's pose in both the camera and the projector")
    Ts = [T_proj_board[i] @ invert_T(T_cam_board[i]) for i in common]
    R = nearest_rotation(np.sum([T[:3, :3] for T in Ts], axis=0))
    t = np.median([T[:3, 3] for T in Ts], axis=0)
    return make_T(R, t)


@dataclass(frozen=True, eq=False)
class BundleResult:
    """Jointly refined camera and projector.

    ``camera`` has ``T_world_cam`` = identity and ``projector`` its pose in the camera frame (world = camera).
    ``rms_camera``, ``rms_projector``: reprojection RMS in each device's pixels. ``view_rms``: per view
    index, (camera RMS, projector RMS) in px. ``T_cam_board``: refined board poses. ``cost``: final
    least-squares cost; ``nfev``: function evaluations.
    """

    camera: PinholeCamera
    projector: PinholeCamera
    rms_camera: float
    rms_projector: float
    view_rms: dict
    T_cam_board: dict
    nfev: int

    @property
    def T_cam_proj(self) -> np.ndarray:
        return self.projector.T_world_cam


def bundle_adjust(camera: PinholeCamera, projector: PinholeCamera, T_proj_cam: np.ndarray,
                  T_cam_board: dict, object_points: np.ndarray, cam_obs: dict, proj_obs: dict, *,
                  sigma_camera: float = 0.05, sigma_projector: float = 0.1, max_nfev: int = 200,
                  fixed_camera: tuple[str, ...] = (), fixed_projector: tuple[str, ...] = (),
                  solver: str = "schur") -> BundleResult:
    """Joint refinement of both devices' intrinsics, their relative pose and the board poses.

    Parameters
    ----------
    camera, projector : initial models (their poses are ignored); k3 stays at its initial value.
    T_proj_cam : (4, 4) initial projector pose relative to the camera (maps camera to projector coordinates).
    T_cam_board : view index -> (4, 4) initial board pose in the camera frame.
    object_points : (N, 3) board corners, metres.
    cam_obs, proj_obs : view index -> (ids (n,), uv (n, 2)) corners seen by the camera / the projector.
    sigma_camera, sigma_projector : expected noise of each device's corners (px); residuals are divided by
        them, so the two devices are weighted by their precision.
    max_nfev : iteration limit of ``least_squares``.
    fixed_camera, fixed_projector : intrinsics held at their initial values (names of :data:`rangekit.calib.bundle.problem.INTRINSICS`;
        "aspect" keeps fy / fx), e.g. ``("k2", "p1", "p2")`` for a lens model of k1 alone.

    solver : "schur" (default): Levenberg-Marquardt on the reduced system, the board poses eliminated through the
        Schur complement, with the analytic Jacobian (:mod:`rangekit.calib.bundle.schur`,
        :mod:`rangekit.calib.projection_jacobian`); "minpack": MINPACK's Levenberg-Marquardt
        (``scipy.optimize.least_squares``) on a Jacobian of grouped finite differences, as before issue 38. Both
        reach the same minimum (tests/calib/test_bundle_schur.py).

    Outliers are the caller's business (the corner fit drops corners it cannot estimate, and
    :func:`rangekit.calib.calibrate_device` rejects bad views).
    """
    if solver not in ("schur", "minpack"):
        raise CalibrationError(f"bundle_adjust: solver must be 'schur' or 'minpack', found {solver!r}")
    problem = make_bundle_problem(camera, projector, T_proj_cam, T_cam_board, object_points, cam_obs, proj_obs,
                                  sigma_camera=sigma_camera, sigma_projector=sigma_projector,
                                  fixed_camera=fixed_camera, fixed_projector=fixed_projector)
    if solver == "minpack":
        sol = least_squares(problem.residuals, problem.x0[problem.free], jac=problem.finite_difference_jacobian(),
                            method="lm", x_scale="jac", max_nfev=max_nfev, xtol=1e-12, ftol=1e-12, gtol=1e-12)
        x_free, nfev = sol.x, int(sol.nfev)
    else:
        from rangekit.calib.bundle.reduced import solve_bundle_reduced

        p = problem
        x_free, nfev = solve_bundle_reduced(p.x0, p.free, p.ties, p.base, len(p.views), p.obs_view, p.obs_cam,
                                            p.obs_X, p.obs_uv, p.obs_sigma, p.k3c, p.k3p, max_nfev)
    return _bundle_result(problem, camera, projector, x_free, nfev)


def _bundle_result(problem: BundleProblem, camera: PinholeCamera, projector: PinholeCamera, x_free: np.ndarray,
                   nfev: int) -> BundleResult:
    """The :class:`BundleResult` at the solution ``x_free`` (the problem's free parameters): both devices (world =
    the camera's frame; ``camera``'s and ``projector``'s sizes and names), the reprojection RMS per device and view
    in pixels, the board poses."""
    x = problem.full(x_free)
    ic, ip, R_pc, t_pc = problem.unpack(x)
    raw = problem.residuals(x_free, scaled=False)
    sq = {"camera": [], "projector": []}
    view_rms = {}
    for k, device, ids, _, r0 in problem.blocks:
        e2 = raw[r0:r0 + 2 * len(ids)].reshape(-1, 2)
        d2 = np.sum(e2 ** 2, axis=1)
        sq[device].append(d2)
        view_rms.setdefault(problem.views[k], [np.nan, np.nan])[0 if device == "camera" else 1] = \
            float(np.sqrt(d2.mean()))
    rms = {d: float(np.sqrt(np.concatenate(v).mean())) if v else float("nan") for d, v in sq.items()}

    def model(dev: PinholeCamera, intr: np.ndarray, k3: float, T_world: np.ndarray) -> PinholeCamera:
        K = np.array([[intr[0], 0, intr[2]], [0, intr[1], intr[3]], [0, 0, 1]])
        return PinholeCamera(K=K, width=dev.width, height=dev.height,
                             dist=np.array([intr[4], intr[5], intr[6], intr[7], k3]), T_world_cam=T_world,
                             name=dev.name)

    T_proj_cam_final = make_T(R_pc, t_pc)
    cam = model(camera, ic, problem.k3c, np.eye(4))
    proj = model(projector, ip, problem.k3p, invert_T(T_proj_cam_final))
    base = problem.base
    poses = {v: make_T(rotvec_to_R(x[base + 6 * k: base + 6 * k + 3]), x[base + 6 * k + 3: base + 6 * k + 6])
             for k, v in enumerate(problem.views)}
    return BundleResult(camera=cam, projector=proj, rms_camera=rms["camera"], rms_projector=rms["projector"],
                        view_rms={v: tuple(r) for v, r in view_rms.items()}, T_cam_board=poses, nfev=nfev)
