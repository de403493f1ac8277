"""The camera-projector bundle adjustment (:func:`rangekit.calib.projector.bundle_adjust`) posed for the reduced
system: its residuals and analytic Jacobian (:mod:`rangekit.calib.projection_jacobian`) in the shared columns and
one 6-column block per board pose, solved by :func:`rangekit.calib.bundle.schur.solve_reduced_lm`."""

from __future__ import annotations

import numpy as np

from rangekit.calib.projection_jacobian import (N_INTRINSICS as _N_INTR, pixel_jacobian, project as _project,
                                                rotated_right_jacobian, rotation_jacobian, skew)
from rangekit.errors import CalibrationError
from rangekit.geometry import rotvec_to_R

__all__ = ["solve_bundle_reduced"]


def solve_bundle_reduced(x0, free, ties, base, n_views, obs_view, obs_cam, obs_X, obs_uv, obs_sigma, k3c, k3p, max_nfev):
    """:func:`rangekit.calib.projector.bundle_adjust`'s problem on the reduced system (``solver="schur"``): the free parameters at the
    minimum and the number of evaluations. Rows are ordered by board pose (the observations' order is)."""
    from rangekit.calib.bundle.schur import solve_reduced_lm

    shared_free = np.flatnonzero(free[:base])
    n = len(obs_uv)
    row_view = np.repeat(obs_view, 2)
    if np.any(np.diff(row_view) < 0):
        raise CalibrationError("bundle_adjust: observations must be grouped by board pose")
    starts = np.searchsorted(row_view, np.arange(n_views + 1))
    inv_sigma = (1.0 / obs_sigma).repeat(2, axis=1)                      # (n, 2)

    def shared_full(g):
        x = x0[:base].copy()
        x[shared_free] = g
        for dst, src, ratio in ties:
            x[dst] = x[src] * ratio
        return x

    def evaluate(g, poses, jacobian):
        x = shared_full(g)
        ic, ip = x[:_N_INTR], x[_N_INTR:2 * _N_INTR]
        r_pc, t_pc = x[2 * _N_INTR:2 * _N_INTR + 3], x[2 * _N_INTR + 3:base]
        R_pc = rotvec_to_R(r_pc)
        R_k = rotvec_to_R(poses[:, :3])                                  # (K, 3, 3)
        Pc = np.einsum("nij,nj->ni", R_k[obs_view], obs_X) + poses[obs_view, 3:]
        if not jacobian:
            pred = np.empty((n, 2))
            pred[obs_cam] = _project(Pc[obs_cam], ic, k3c)
            pred[~obs_cam] = _project(Pc[~obs_cam] @ R_pc.T + t_pc, ip, k3p)
            return ((pred - obs_uv) * inv_sigma).ravel(), None, None
        # d(R X)/dr = -[R X]_x (R J_r(r)): the 3 x 3 R J_r once per pose (rotation_jacobian's identity).
        dPc = np.empty((n, 3, 6))
        dPc[:, :, :3] = -skew(Pc - poses[obs_view, 3:]) @ rotated_right_jacobian(poses[:, :3])[obs_view]
        dPc[:, :, 3:] = np.eye(3)
        uv = np.empty((n, 2))
        Jg = np.zeros((n, 2, base))
        Jp = np.empty((n, 2, 6))
        c, q = obs_cam, ~obs_cam
        uv[c], J_intr, J_P = pixel_jacobian(Pc[c], ic, k3c)
        Jg[c, :, :_N_INTR] = J_intr
        Jp[c] = J_P @ dPc[c]
        Pp = Pc[q] @ R_pc.T + t_pc
        uv[q], J_intr, J_P = pixel_jacobian(Pp, ip, k3p)
        Jg[q, :, _N_INTR:2 * _N_INTR] = J_intr
        Jg[q, :, 2 * _N_INTR:2 * _N_INTR + 3] = J_P @ rotation_jacobian(r_pc, Pc[q])
        Jg[q, :, 2 * _N_INTR + 3:base] = J_P
        Jp[q] = J_P @ R_pc @ dPc[q]
        for dst, src, ratio in ties:                                    # fy = ratio * fx moves with fx
            Jg[:, :, src] += ratio * Jg[:, :, dst]
        scale = inv_sigma[:, :, None]
        return (((uv - obs_uv) * inv_sigma).ravel(), (Jg[:, :, shared_free] * scale).reshape(2 * n, -1),
                (Jp * scale).reshape(2 * n, 6))

    sol = solve_reduced_lm(evaluate, x0[:base][shared_free], x0[base:].reshape(n_views, 6), starts,
                           max_iterations=max_nfev)
    x_free = np.concatenate([sol.shared, sol.poses.ravel()])
    return x_free, sol.evaluations
