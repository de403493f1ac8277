"""Poses that a turntable can give: every view rotated about one common axis.

On a turntable the views' poses are not 6(n-1) free motions: they are rotations ``theta_k`` about one
axis (a line: 4 parameters). Refining inside that family (the axis and the angles) keeps every view
consistent with the others where the data alone leave a motion weak: objects made of a few plane
directions (a step gauge, thin fins and pins) let pairs of views slide along their planes, and a free
joint refinement drifts there (0.9 mm on the simulated step gauge) while the turntable model cannot.

- :func:`common_axis`: the axis (unit direction, a point on it) that best explains a set of poses.
- :func:`onto_turntable`: the nearest poses of that family (the common axis, each view's angle about it).
- :func:`swept_voxel`: the registration's voxel from the first view alone, the box its points sweep on the
  table (a scan's registration can then start before the last view is in).
- :func:`turntable_basis`: the (6(n-1), n-1+4) basis of the small motions of views 1..n-1 (view 0 is the
  world) that keep all the poses rotations about one axis, in the joint refinement's coordinates: each
  view's ``xi = (omega, v)``, a rotation ``omega`` about ``centre`` followed by a translation ``v``.

Metres, radians; poses are ``T_world_view`` (4, 4) with ``T_world_view[0]`` the identity.
"""

from __future__ import annotations

import numpy as np

from rangekit.errors import RegistrationError
from rangekit.geometry import R_to_rotvec, make_T, rotvec_to_R

__all__ = ["common_axis", "onto_turntable", "turntable_basis", "swept_voxel", "SWEPT_VOXELS"]

#: The swept box's diagonal in voxels (:func:`swept_voxel`). Every view's own box holds what the views saw, a
#: smaller box than the one the first view's points sweep round the axis: on the default 12-view scan 0.230 m
#: against 0.268 m, so 110 voxels of the one (the voxel of :func:`rangekit.registration.multiview.register_views`
#: by default) are 128 of the other: 2.09 mm both.
SWEPT_VOXELS = 128


def common_axis(T_world_view: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(direction (3,), point (3,))`` of the axis the poses (n, 4, 4) rotate about: the direction the
    mean of the rotation vectors (signs aligned), the point the least-squares solution of
    ``(I - R_k) o = t_k`` nearest the origin. Raises RegistrationError when no pose rotates."""
    T = np.asarray(T_world_view, dtype=np.float64)
    rv = np.array([R_to_rotvec(t[:3, :3]) for t in T])
    big = np.linalg.norm(rv, axis=1) > 1e-6
    if not big.any():
        raise RegistrationError("turntable: the poses do not rotate; there is no axis to refine")
    ref = rv[big][np.argmax(np.linalg.norm(rv[big], axis=1))]
    rv = np.where((rv @ ref)[:, None] < 0, -rv, rv)
    a = rv[big].sum(axis=0)
    a /= np.linalg.norm(a)
    A = np.concatenate([np.eye(3) - t[:3, :3] for t in T[big]])
    b = np.concatenate([t[:3, 3] for t in T[big]])
    o = np.linalg.lstsq(A, b, rcond=None)[0]
    o -= a * (a @ o)   # the point of the axis nearest the origin
    return a, o


def onto_turntable(T_world_view: np.ndarray) -> np.ndarray:
    """(n, 4, 4): each pose replaced by the rotation about :func:`common_axis` by its own rotation's
    component along that axis (``X -> R (X - o) + o``)."""
    T = np.asarray(T_world_view, dtype=np.float64)
    a, o = common_axis(T)
    out = []
    for t in T:
        R = rotvec_to_R(a * float(R_to_rotvec(t[:3, :3]) @ a))
        out.append(make_T(R, o - R @ o))
    return np.array(out)


def _adjoint(T: np.ndarray, centre: np.ndarray) -> np.ndarray:
    """(6, 6): ``T exp(xi) T^-1 = exp(Ad xi)`` for twists ``xi = (omega, v)`` about ``centre``."""
    R, t = T[:3, :3], T[:3, 3]
    lever = centre - R @ centre - t
    skew = np.array([[0.0, -lever[2], lever[1]], [lever[2], 0.0, -lever[0]], [-lever[1], lever[0], 0.0]])
    Ad = np.zeros((6, 6))
    Ad[:3, :3] = R
    Ad[3:, 3:] = R
    Ad[3:, :3] = -skew @ R   # (R omega) x lever = -[lever]x R omega
    return Ad


def turntable_basis(T_world_view: np.ndarray, centre: np.ndarray, length: float) -> np.ndarray:
    """(6(n-1), m) orthonormal basis (in the scaled coordinates ``(length * omega, v)``, returned as
    ``(omega, v)``) of the updates of views 1..n-1 that keep the poses rotations about one axis: one
    rotation about the axis per view and the 4 motions of the axis (see the module docstring).

    ``length`` (metres) scales rotations against translations (the object's size)."""
    T = np.asarray(T_world_view, dtype=np.float64)
    n = len(T)
    a, o = common_axis(T)
    cols = []
    for k in range(1, n):
        c = np.zeros(6 * (n - 1))
        c[6 * (k - 1): 6 * k] = np.concatenate([a, np.cross(a, centre - o)])   # rotation about the axis
        cols.append(c)
    for e in np.eye(6):   # the axis moved by a small motion e of the world: T_k -> (I + e) T_k (I - e)
        cols.append(np.concatenate([e - _adjoint(T[k], centre) @ e for k in range(1, n)]))
    B = np.array(cols).T
    B[np.tile(np.arange(6) < 3, n - 1)] *= length
    U, s, _ = np.linalg.svd(B, full_matrices=False)
    B = U[:, s > 1e-9 * s.max()]
    B[np.tile(np.arange(6) < 3, n - 1)] /= length
    return B


def swept_voxel(points: np.ndarray, T_world_view: np.ndarray) -> float:
    """Metres: the diagonal of the box that the first view's ``points`` ((N, 3), its own frame) fill when carried
    into every view's frame by the poses ``T_world_view`` ((n, 4, 4), world = the first view's frame), divided by
    :data:`SWEPT_VOXELS`; about 2000 of the points (every k-th) are used, as
    :func:`rangekit.surface.cloud.bbox_diagonal` does. Known from the first view and the prior alone."""
    P = np.asarray(points, dtype=np.float64)[::max(1, len(points) // 2000)]
    T = np.asarray(T_world_view, dtype=np.float64)
    inv = np.linalg.inv(T)                                  # view 0's frame into view k's
    swept = np.einsum("kij,nj->kni", inv[:, :3, :3], P) + inv[:, None, :3, 3]
    swept = swept.reshape(-1, 3)
    return float(np.linalg.norm(swept.max(axis=0) - swept.min(axis=0))) / SWEPT_VOXELS
