"""Geometric stability of a point-to-plane registration (Gelfand, Ikemoto, Rusinkiewicz, Levoy, "Geometrically
stable sampling for the ICP algorithm", 3DIM 2003): which rigid motions the overlapping surface constrains.

A small motion of the source, rotation ``omega`` about the centroid ``m`` of the correspondences and
translation ``t``, changes the point-to-plane residual of a correspondence (point p, normal n) by
``((p - m) x n) . omega + n . t``. Scaling the lever arm by the RMS radius ``L`` of the points makes
rotations and translations comparable (a rotation of 1 rad moves a typical point by ``L``); the 6x6 matrix

    C = sum_i w_i [(p_i - m) x n_i / L; n_i] [(p_i - m) x n_i / L; n_i]^T

has an eigenvector for each independent motion, and its eigenvalue says how much the residuals change
along it. A motion whose eigenvalue is below :data:`MIN_CONSTRAINT` times the largest is *unconstrained*:
the surface slides along it (a plane: 2 translations and the rotation about its normal; a sphere: the 3
rotations about its centre; a cylinder: the rotation about and translation along its axis; a surface of
revolution: the rotation about its axis; a helix: a screw motion). Any pose along such a motion fits the
data equally well, so ICP returns whatever the noise or the start picked.

Threshold (measured; registration runs on voxel-downsampled clouds, 2 voxel ICP gate). Exact analytic
surfaces give ratios below 1e-12, sampled on a voxel grid with estimated normals about 1e-4, and 2e-4 to
4e-4 with point noise of 0.04 voxel (the normals' noise counts as a constraint: the ratio grows with
the squared normal error, about 6e-4 at 0.12 voxel, 0.015 at 0.4 voxel, where no ratio test can tell
noise from shape). Well-posed pairs: Stanford bunny (10 views) 0.017 or more; the smooth lumpy
simulator object, 12 turntable views, 0.001 or more, down to 0.0010 for pairs overlapping by 25 %.
``MIN_CONSTRAINT = 5e-4`` sits between: clean or low-noise planes, spheres, cylinders and surfaces of
revolution are caught; a noisier one is not flagged and registers as before.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from rangekit.geometry import make_T, rotvec_to_R

__all__ = ["MIN_CONSTRAINT", "PoseConstraint", "HeldMotions", "pose_constraint", "motion_T", "held_step",
           "describe_motions"]

MIN_CONSTRAINT = 5e-4   # smallest eigenvalue / largest of C below which a motion is unconstrained
_TRANSLATION_BELOW = 0.3  # a unit motion (L omega, t) with |L omega| below this is described as a translation


class HeldMotions(NamedTuple):
    """Rigid motions a registration must not move along: rows ``(L omega, t)`` (k, 6), unit, rotation
    ``omega`` about ``centre`` (3,) metres, ``length`` L metres."""

    motions: np.ndarray
    centre: np.ndarray
    length: float

    def describe(self) -> str:
        return describe_motions(self.motions, self.centre, self.length)


@dataclass(frozen=True, eq=False)
class PoseConstraint:
    """How well the correspondences of a registration fix each rigid motion.

    ``eigenvalues`` (6,) ascending, divided by the largest (the last is 1); ``motions`` (6, 6): row k the
    unit eigenvector ``(L omega, t)`` of eigenvalue k (rotation ``omega`` in radians about ``centre``,
    translation ``t`` in metres, in the frame of the points); ``centre`` (3,) metres; ``length`` the RMS
    distance ``L`` of the points from the centre, metres.
    """

    eigenvalues: np.ndarray
    motions: np.ndarray
    centre: np.ndarray
    length: float

    @property
    def ratio(self) -> float:
        """Smallest eigenvalue / largest: 0 for a surface that slides, up to 1 (well constrained)."""
        return float(self.eigenvalues[0])

    def unconstrained(self, threshold: float = MIN_CONSTRAINT) -> np.ndarray:
        """(k, 6) motions ``(L omega, t)`` whose eigenvalue ratio is below ``threshold``."""
        return self.motions[self.eigenvalues < threshold]

    def describe(self, threshold: float = MIN_CONSTRAINT) -> str:
        """The unconstrained motions in words ('' when every motion is constrained)."""
        return describe_motions(self.unconstrained(threshold), self.centre, self.length)

    def held(self, threshold: float = MIN_CONSTRAINT) -> HeldMotions:
        """The unconstrained motions, to keep a prior along them (:func:`held_step`), expressed about the
        point their rotations leave most nearly fixed (a sphere's centre, the nearest point of a cylinder's
        axis): there the free rotations are pure rotations, so the steps orthogonal to them keep the
        prior's orientation about that point (and its position along free translations)."""
        M = self.unconstrained(threshold)
        omega, t = M[:, :3] / self.length, M[:, 3:]
        # x minimising sum_k |t_k + omega_k x (x - centre)|^2 (least norm: the point nearest the centre).
        A = np.concatenate([np.cross(np.eye(3), w) for w in omega]) if len(M) else np.zeros((0, 3))
        y = np.linalg.lstsq(A, -t.reshape(-1), rcond=1e-6)[0] if len(M) else np.zeros(3)
        return HeldMotions(np.hstack([M[:, :3], t + np.cross(omega, y)]), self.centre + y, self.length)


def _lever_rows(points: np.ndarray, normals: np.ndarray, weights: np.ndarray | None):
    p = np.asarray(points, dtype=np.float64)
    n = np.asarray(normals, dtype=np.float64)
    w = np.ones(len(p)) if weights is None else np.asarray(weights, dtype=np.float64)
    centre = (w @ p) / max(w.sum(), 1e-300)
    length = float(np.sqrt((w @ np.sum((p - centre) ** 2, axis=1)) / max(w.sum(), 1e-300)))
    return np.hstack([np.cross(p - centre, n) / max(length, 1e-300), n]), w, centre, length


def pose_constraint(points: np.ndarray, normals: np.ndarray, weights: np.ndarray | None = None) -> PoseConstraint:
    """The constraint matrix of correspondences with target ``points`` (N, 3) and unit ``normals`` (N, 3)
    (metres, one frame) and optional ``weights`` (N,); see the module docstring. Fewer than 6 points
    leave some motion free by construction (ratio 0)."""
    J, w, centre, length = _lever_rows(points, normals, weights)
    C = J.T @ (J * w[:, None])
    vals, vecs = np.linalg.eigh(C)
    top = vals[-1] if vals[-1] > 0 else 1.0
    return PoseConstraint(np.clip(vals / top, 0.0, None), vecs.T.copy(), centre, length)


def motion_T(motion: np.ndarray, centre: np.ndarray, length: float, s: float = 1.0) -> np.ndarray:
    """(4, 4) the rigid motion ``s * (L omega, t)``: rotation ``s omega`` about ``centre``, then ``s t``."""
    R = rotvec_to_R(s * np.asarray(motion[:3]) / length)
    return make_T(R, centre - R @ centre + s * np.asarray(motion[3:]))


def held_step(J: np.ndarray, r: np.ndarray, w: np.ndarray, lever: np.ndarray, k: int,
              hold: HeldMotions) -> np.ndarray | None:
    """The Gauss-Newton step ``x = (omega, t)`` of the weighted ``J x = -r`` (rotation about the origin,
    as :func:`rangekit.registration.icp` solves it) with no component along the motions of ``hold``
    (unit ``(L omega, t)`` about ``hold.centre``): the start pose is kept along them.
    ``lever`` (N, 3) is what the rotation columns cross the normals with (p, or p + q for the symmetric
    objective, then ``k = 2``). None if the reduced system is singular."""
    c, L = hold.centre, hold.length
    n = J[:, 3:]
    Js = np.hstack([np.cross(lever - k * c, n) / (k * L), n])      # unknowns y = (k L omega, t_c)
    free = np.asarray(hold.motions).reshape(-1, 6)
    B = np.linalg.svd(free, full_matrices=True)[2][len(free):].T   # (6, 6 - k) the complement
    Jb = Js @ B
    A = Jb.T @ (Jb * w[:, None])
    try:
        z = np.linalg.solve(A + 1e-12 * np.trace(A) / len(A) * np.eye(len(A)), -Jb.T @ (w * r))
    except np.linalg.LinAlgError:
        return None
    y = B @ z
    omega = y[:3] / (k * L)
    x = np.r_[omega, y[3:] - k * np.cross(omega, c)]
    return x if np.all(np.isfinite(x)) else None


def _vec(v: np.ndarray) -> str:
    v = v / np.linalg.norm(v)
    if v[np.argmax(np.abs(v))] < 0:
        v = -v
    v = np.round(v, 2) + 0.0   # no "-0.00"
    return f"({v[0]:.2f}, {v[1]:.2f}, {v[2]:.2f})"


def _mm(x: np.ndarray) -> str:
    return f"({x[0] * 1e3:.1f}, {x[1] * 1e3:.1f}, {x[2] * 1e3:.1f}) mm"


def describe_motions(motions: np.ndarray, centre: np.ndarray, length: float) -> str:
    """Name a subspace of rigid motions: its translations ('translation along D', 'in the plane normal
    to N', 'in any direction') and its rotations (axis direction and a point on the axis, 'any axis
    through X' for three rotations about one point, a pitch for screw motions). ``motions`` (k, 6) rows
    ``(L omega, t)`` about ``centre``."""
    M = np.asarray(motions, dtype=np.float64).reshape(-1, 6)
    if len(M) == 0:
        return ""
    # Combinations of the (unit) motions whose rotation part ``L omega`` is small are translations (a
    # rotation about an axis more than about 3 L from the centre is one too, locally); the rest rotate.
    _, s, Vt = np.linalg.svd(M[:, :3].T, full_matrices=True)
    s = np.r_[s, np.zeros(len(M) - len(s))]
    rot = s > _TRANSLATION_BELOW
    omega = M[:, :3] / length
    t = M[:, 3:]
    trans = Vt[~rot] @ t                      # (kt, 3) translations
    parts = []
    if len(trans):
        _, st, Vt_t = np.linalg.svd(trans)
        kt = int(np.sum(st > 0.1 * max(st[0], 1e-300)))
        if kt == 1:
            parts.append(f"translation along {_vec(Vt_t[0])}")
        elif kt == 2:
            parts.append(f"translation in the plane normal to {_vec(Vt_t[2])}")
        elif kt == 3:
            parts.append("translation in any direction")
        T_basis = Vt_t[:kt]
    else:
        T_basis = np.zeros((0, 3))
    if np.any(rot):
        R = Vt[rot]
        om = R @ omega                         # (kr, 3) rotation vectors
        tr = R @ t
        tr = tr - (tr @ T_basis.T) @ T_basis   # drop the free translations: canonical axes
        if len(om) == 3:
            # Three rotations about one point x: t_k = -omega_k x (x - centre) for every k.
            A = np.concatenate([np.cross(np.eye(3), w) for w in om])  # [omega_k]x stacked: A x = omega_k x x
            x, *_ = np.linalg.lstsq(A, -tr.reshape(-1), rcond=None)
            if np.linalg.norm(A @ x + tr.reshape(-1)) <= 0.1 * length * np.linalg.norm(om):
                parts.insert(0, f"rotation about any axis through {_mm(centre + x)}")
                om = om[:0]
        for w, v in zip(om, tr):
            w2 = float(w @ w)
            point = centre + np.cross(w, v) / w2    # the point of the axis nearest the centre
            pitch = float(w @ v) / w2               # metres per radian
            kind = "rotation" if abs(pitch) < 0.1 * length else f"screw motion (pitch {pitch * 1e3:.2f} mm/rad)"
            parts.insert(0, f"{kind} about {_vec(w)} through {_mm(point)}")
    return "; ".join(parts)
