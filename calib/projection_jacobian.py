"""The analytic Jacobian of a board corner's projection, for the bundle adjustment
(:func:`rangekit.calib.projector.bundle_adjust`).

A corner ``X`` of board pose k is seen by the camera at ``P_c = R(r_k) X + t_k`` and by the projector at
``P_p = R(r_pc) P_c + t_pc``; a device with intrinsics ``(fx, fy, cx, cy, k1, k2, p1, p2)`` (k3 held) sees
``P = (X, Y, Z)`` at ``u = fx xd + cx``, ``v = fy yd + cy``, ``(xd, yd)`` the distorted ``(X/Z, Y/Z)``
(:func:`rangekit.lens.distort`). The derivatives:

- of the pixel in the intrinsics: ``(xd, 0)``, ``(0, yd)``, ``(1, 0)``, ``(0, 1)``, then ``(fx x r^2, fy y r^2)``,
  ``(fx x r^4, fy y r^4)``, ``(2 fx x y, fy (r^2 + 2 y^2))``, ``(fx (r^2 + 2 x^2), 2 fy x y)``;
- of the pixel in ``P``: ``diag(fx, fy) D(x, y) [[1/Z, 0, -X/Z^2], [0, 1/Z, -Y/Z^2]]``, ``D`` the Jacobian of the
  distortion (:func:`rangekit.camera.distort_jacobian`);
- of a rotated point ``R(r) v`` in the rotation vector: ``-R(r) [v]_x J_r(r) = -[R(r) v]_x R(r) J_r(r)``, ``J_r``
  the right Jacobian of SO(3), ``I - (1 - cos t)/t^2 [r]_x + (t - sin t)/t^3 [r]_x^2`` (t = |r|): ``R J_r`` once per
  pose; of ``R(r) v + t`` in ``t``: I.

tests/calib/test_bundle_schur.py checks every column against central finite differences.
"""

from __future__ import annotations

import numpy as np

from rangekit.camera import distort, distort_jacobian
from rangekit.geometry import rotvec_to_R

__all__ = ["N_INTRINSICS", "project", "pixel_jacobian", "rotated_right_jacobian", "rotation_jacobian", "skew"]


#: Intrinsics a device's bundle adjustment refines: fx, fy, cx, cy, k1, k2, p1, p2 (k3 kept at its initial value).
N_INTRINSICS = 8


def project(points_dev: np.ndarray, intr: np.ndarray, k3: float) -> np.ndarray:
    """Pixels (n, 2) of device-frame points (n, 3) through intrinsics ``intr`` (8,) and ``k3``."""
    z = points_dev[:, 2:3]
    xy = points_dev[:, :2] / z
    dist = np.array([intr[4], intr[5], intr[6], intr[7], k3])
    xy = distort(xy, dist)
    return np.column_stack([intr[0] * xy[:, 0] + intr[2], intr[1] * xy[:, 1] + intr[3]])


def skew(v: np.ndarray) -> np.ndarray:
    """(n, 3, 3) cross-product matrices of (n, 3) vectors."""
    S = np.zeros(v.shape[:-1] + (3, 3))
    S[..., 0, 1], S[..., 0, 2], S[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    S[..., 1, 0], S[..., 2, 0], S[..., 2, 1] = v[..., 2], -v[..., 1], v[..., 0]
    return S


def rotated_right_jacobian(r: np.ndarray) -> np.ndarray:
    """(n, 3, 3): ``R(r_i) J_r(r_i)`` for rotation vectors ``r`` (n, 3); ``d(R(r) v)/dr = -[R(r) v]_x`` times it."""
    r = np.array(r, dtype=np.float64, ndmin=2)
    theta = np.linalg.norm(r, axis=-1)[..., None, None]
    K = skew(r)
    small = theta < 1e-8
    t = np.where(small, 1.0, theta)
    a = np.where(small, 0.5, (1 - np.cos(t)) / t ** 2)
    b = np.where(small, 1.0 / 6.0, (t - np.sin(t)) / t ** 3)
    return rotvec_to_R(r) @ (np.eye(3) - a * K + b * (K @ K))


def rotation_jacobian(r: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(n, 3, 3): d(R(r_i) v_i)/d r_i for rotation vectors ``r`` (n, 3) or (3,) and points ``v`` (n, 3)."""
    r = np.array(np.broadcast_to(np.asarray(r, np.float64), np.shape(v)))
    return -skew(np.einsum("nij,nj->ni", rotvec_to_R(r), v)) @ rotated_right_jacobian(r)


def pixel_jacobian(P: np.ndarray, intr: np.ndarray, k3: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Pixels (n, 2) of device-frame points ``P`` (n, 3) through intrinsics ``intr`` (8,) and k3, with their
    Jacobians in the intrinsics (n, 2, 8) and in ``P`` (n, 2, 3)."""
    X, Y, Z = P[:, 0], P[:, 1], P[:, 2]
    xy = P[:, :2] / Z[:, None]
    x, y = xy[:, 0], xy[:, 1]
    dist = np.array([intr[4], intr[5], intr[6], intr[7], k3])
    xd = distort(xy, dist)
    fx, fy = intr[0], intr[1]
    uv = np.column_stack([fx * xd[:, 0] + intr[2], fy * xd[:, 1] + intr[3]])
    r2 = x * x + y * y
    J_intr = np.zeros((len(P), 2, 8))
    J_intr[:, 0, 0], J_intr[:, 1, 1] = xd[:, 0], xd[:, 1]
    J_intr[:, 0, 2], J_intr[:, 1, 3] = 1.0, 1.0
    J_intr[:, 0, 4], J_intr[:, 1, 4] = fx * x * r2, fy * y * r2
    J_intr[:, 0, 5], J_intr[:, 1, 5] = fx * x * r2 * r2, fy * y * r2 * r2
    J_intr[:, 0, 6], J_intr[:, 1, 6] = fx * 2 * x * y, fy * (r2 + 2 * y * y)
    J_intr[:, 0, 7], J_intr[:, 1, 7] = fx * (r2 + 2 * x * x), fy * 2 * x * y
    J_norm = np.zeros((len(P), 2, 3))
    J_norm[:, 0, 0] = J_norm[:, 1, 1] = 1.0 / Z
    J_norm[:, 0, 2], J_norm[:, 1, 2] = -X / Z ** 2, -Y / Z ** 2
    J_P = np.array([fx, fy])[None, :, None] * (distort_jacobian(xy, dist) @ J_norm)
    return uv, J_intr, J_P
