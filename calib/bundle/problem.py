"""The camera-projector bundle adjustment as a problem object (:class:`BundleProblem`): its parameter vector, which
entries vary, the observations in residual-row order, and the residuals and finite-difference Jacobian over them.

Parameters (``x``, float64): the camera's intrinsics (:data:`INTRINSICS`: fx, fy, cx, cy in pixels, k1, k2, p1, p2),
the projector's, the projector's pose relative to the camera ``T_proj_cam`` (rotation vector in radians,
translation in metres), then each board pose ``T_cam_board`` (the same six). k3 is held at its initial value.
Residuals: per observed corner and device, the predicted minus the measured pixel (u, v), divided by that device's
noise (px) when scaled. :func:`rangekit.calib.projector.bundle_adjust` solves it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy.sparse import lil_matrix

from rangekit.calib.projection_jacobian import N_INTRINSICS as _N_INTR, project as _project
from rangekit.camera import PinholeCamera
from rangekit.errors import CalibrationError
from rangekit.geometry import R_to_rotvec, rotvec_to_R

__all__ = ["INTRINSICS", "BundleProblem", "make_bundle_problem", "intrinsics_vector"]

#: The intrinsics a bundle adjustment refines, in the order of each device's block of the parameter vector; a
#: ``fixed_*`` name holds one at its initial value, "aspect" keeps fy at fx times its initial ratio.
INTRINSICS = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2")


def free_intrinsics(fixed, device: str) -> np.ndarray:
    """(8,) bool: which of :data:`INTRINSICS` vary; CalibrationError naming an unknown name."""
    unknown = sorted(set(fixed) - set(INTRINSICS) - {"aspect"})
    if unknown:
        raise CalibrationError(f"bundle_adjust: fixed_{device}: expected names among {', '.join(INTRINSICS)}, "
                               f"aspect; found {', '.join(map(repr, unknown))}")
    return np.array([n not in fixed and not (n == "fy" and "aspect" in fixed) for n in INTRINSICS])


def intrinsics_vector(dev: PinholeCamera) -> np.ndarray:
    """(8,) float64 a device's :data:`INTRINSICS` (distortion beyond p2 dropped, missing terms 0)."""
    d = np.zeros(5)
    d[:min(5, len(dev.dist))] = dev.dist[:5]
    K = dev.K
    return np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2], d[0], d[1], d[2], d[3]])


@dataclass(frozen=True, eq=False)
class BundleProblem:
    """A bundle adjustment's data (module doc). ``views``: the board views' indices in parameter order; ``x0``
    (2 * 8 + 6 + 6 V,) the starting parameters; ``free`` (same,) bool which vary; ``ties``: (entry, source, ratio)
    of each fy kept at its fx's ratio; ``blocks``: (view k, device, ids (n,), uv (n, 2), first residual row) per
    device's view of the board, in row order; ``obs_*`` (M,) every observation: its view k, whether the camera saw
    it, its corner (M, 3) metres in the board frame, its measured pixel (M, 2) and noise (M, 1) px; ``k3c``,
    ``k3p``: the devices' held k3."""

    views: list
    x0: np.ndarray
    free: np.ndarray
    ties: list
    blocks: list
    obs_view: np.ndarray
    obs_cam: np.ndarray
    obs_X: np.ndarray
    obs_uv: np.ndarray
    obs_sigma: np.ndarray
    k3c: float
    k3p: float

    @property
    def base(self) -> int:
        """The first board pose's entry in the parameter vector."""
        return 2 * _N_INTR + 6

    @property
    def rows(self) -> int:
        """The number of residuals (two per observation)."""
        return 2 * len(self.obs_view)

    def full(self, x_free: np.ndarray) -> np.ndarray:
        """The whole parameter vector from its free entries (fixed ones at ``x0``, tied ones by their ratio)."""
        x = self.x0.copy()
        x[np.flatnonzero(self.free)] = x_free
        for dst, src, ratio in self.ties:
            x[dst] = x[src] * ratio
        return x

    def unpack(self, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """The camera's and the projector's intrinsics (8,) each, and ``T_proj_cam``'s rotation (3, 3) and
        translation (3,) metres."""
        ic, ip = x[:_N_INTR], x[_N_INTR:2 * _N_INTR]
        R_pc = rotvec_to_R(x[2 * _N_INTR:2 * _N_INTR + 3])
        t_pc = x[2 * _N_INTR + 3:self.base]
        return ic, ip, R_pc, t_pc

    def residuals(self, x_free: np.ndarray, scaled: bool = True) -> np.ndarray:
        """(rows,) predicted minus measured pixels of every observation, (u, v) in turn; divided by each device's
        noise when ``scaled``."""
        x = self.full(x_free)
        ic, ip, R_pc, t_pc = self.unpack(x)
        p = x[self.base:].reshape(-1, 6)
        R = rotvec_to_R(p[:, :3])                                                         # (V, 3, 3)
        X = np.einsum("nij,nj->ni", R[self.obs_view], self.obs_X) + p[self.obs_view, 3:]  # camera frame
        pred = np.empty_like(self.obs_uv)
        pred[self.obs_cam] = _project(X[self.obs_cam], ic, self.k3c)
        pred[~self.obs_cam] = _project(X[~self.obs_cam] @ R_pc.T + t_pc, ip, self.k3p)
        e = pred - self.obs_uv
        return (e / self.obs_sigma if scaled else e).ravel()

    def finite_difference_jacobian(self) -> Callable[[np.ndarray], np.ndarray]:
        """``jacobian(x_free) -> (rows, n_free)`` of the scaled residuals by finite differences in column groups that
        share no residual row: parameter j of every board pose (each pose touches only its own view's rows) moves in
        one evaluation, so a Jacobian costs 2 * 8 + 6 + 6 evaluations whatever the number of views. The result is
        small and solved densely. Columns are positions in the free parameters (a fixed intrinsic has none)."""
        base, free = self.base, self.free
        S = lil_matrix((self.rows, len(self.x0)), dtype=np.int8)
        for k, device, ids, _, r0 in self.blocks:
            r1 = r0 + 2 * len(ids)
            S[r0:r1, base + 6 * k: base + 6 * k + 6] = 1
            if device == "camera":
                S[r0:r1, 0:_N_INTR] = 1
            else:
                S[r0:r1, _N_INTR:2 * _N_INTR + 6] = 1
        position = np.cumsum(free) - 1
        groups = [[position[c]] for c in range(base) if free[c]] + \
            [list(position[base + j::6]) for j in range(6)]
        touches = S.toarray().astype(bool)[:, free]    # a tied fy's rows are its fx's: the device's own rows

        def jacobian(x):
            f0 = self.residuals(x)
            J = np.zeros((self.rows, len(x)))
            for cols in groups:
                h = 1e-7 * np.maximum(np.abs(x[cols]), 1e-2)
                xh = x.copy()
                xh[cols] += h
                df = self.residuals(xh) - f0
                for c, hc in zip(cols, h):
                    J[touches[:, c], c] = df[touches[:, c]] / hc
            return J
        return jacobian


def make_bundle_problem(camera: PinholeCamera, projector: PinholeCamera, T_proj_cam: np.ndarray, T_cam_board: dict,
                        object_points: np.ndarray, cam_obs: dict, proj_obs: dict, *, sigma_camera: float,
                        sigma_projector: float, fixed_camera: tuple[str, ...],
                        fixed_projector: tuple[str, ...]) -> BundleProblem:
    """The :class:`BundleProblem` of :func:`rangekit.calib.projector.bundle_adjust`'s arguments (as it documents
    them); CalibrationError naming an unknown fixed intrinsic."""
    views = sorted(T_cam_board)
    obj = np.asarray(object_points, dtype=np.float64)
    x0 = [intrinsics_vector(camera), intrinsics_vector(projector), R_to_rotvec(T_proj_cam[:3, :3]), T_proj_cam[:3, 3]]
    for v in views:
        T = T_cam_board[v]
        x0 += [R_to_rotvec(T[:3, :3]), T[:3, 3]]
    x0 = np.concatenate(x0)
    free = np.ones(len(x0), bool)
    free[:2 * _N_INTR] = np.concatenate([free_intrinsics(fixed_camera, "camera"),
                                         free_intrinsics(fixed_projector, "projector")])
    # "aspect": fy follows fx at its initial ratio (fy is then not free).
    ties = [(k + 1, k, x0[k + 1] / x0[k]) for k, fixed in ((0, fixed_camera), (_N_INTR, fixed_projector))
            if "aspect" in fixed]
    blocks = []   # (view k, device, ids, uv, row offset)
    rows = 0
    for k, v in enumerate(views):
        for device, obs in (("camera", cam_obs), ("projector", proj_obs)):
            if v in obs and len(obs[v][0]):
                ids, uvs = np.asarray(obs[v][0]), np.asarray(obs[v][1], dtype=np.float64)
                blocks.append((k, device, ids, uvs, rows))
                rows += 2 * len(ids)
    # Every observation at once: its view, device, corner and measured pixel, in the row order of ``blocks``.
    obs_cam = np.concatenate([np.full(len(ids), dev == "camera") for _, dev, ids, _, _ in blocks])
    return BundleProblem(
        views=views, x0=x0, free=free, ties=ties, blocks=blocks,
        obs_view=np.concatenate([np.full(len(ids), k) for k, _, ids, _, _ in blocks]), obs_cam=obs_cam,
        obs_X=obj[np.concatenate([ids for _, _, ids, _, _ in blocks])],
        obs_uv=np.concatenate([uvs for _, _, _, uvs, _ in blocks]),
        obs_sigma=np.where(obs_cam, sigma_camera, sigma_projector)[:, None],
        k3c=float(camera.dist[4]) if len(camera.dist) > 4 else 0.0,
        k3p=float(projector.dist[4]) if len(projector.dist) > 4 else 0.0)
