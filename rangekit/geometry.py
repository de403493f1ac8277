"""Rigid and similarity transforms, rotations, and absolute orientation.

Conventions (see docs/ARCHITECTURE.md): a pose is a 4x4 float64 matrix ``T_a_b`` that maps points from
frame b to frame a, ``p_a = T_a_b @ p_b``. A similarity transform has ``s * R`` in its upper-left 3x3
block. Rotation vectors are axis * angle in radians; quaternions are scalar-last ``(x, y, z, w)`` as in
SciPy. Point sets are (N, 3) float64.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit._runtime.arguments import as_points
from rangekit.errors import InputError

__all__ = [
    "make_T",
    "invert_T",
    "compose",
    "apply_T",
    "transform_vectors",
    "cross_rows",
    "rotvec_to_R",
    "R_to_rotvec",
    "quat_to_R",
    "R_to_quat",
    "axis_angle_to_R",
    "R_up_to_z",
    "nearest_rotation",
    "rotation_angle",
    "look_at",
    "ray_plane_t",
    "ProcrustesResult",
    "procrustes",
]


def _as_points(points: np.ndarray, name: str = "points") -> np.ndarray:
    return as_points(name, points)


def make_T(R: np.ndarray | None = None, t: np.ndarray | None = None, *, scale: float = 1.0) -> np.ndarray:
    """Build a (4, 4) transform ``[scale * R, t; 0 0 0 1]`` (identity parts where omitted)."""
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = scale * np.asarray(R, dtype=np.float64)
    elif scale != 1.0:
        T[:3, :3] *= scale
    if t is not None:
        T[:3, 3] = np.asarray(t, dtype=np.float64).reshape(3)
    return T


def _scale_of(A: np.ndarray) -> float:
    return float(np.cbrt(np.linalg.det(A)))


def invert_T(T: np.ndarray) -> np.ndarray:
    """Invert a rigid or similarity (4, 4) transform exactly (``T_b_a`` from ``T_a_b``)."""
    T = np.asarray(T, dtype=np.float64)
    A = T[:3, :3]
    s = _scale_of(A)
    R = A / s
    out = np.eye(4)
    out[:3, :3] = R.T / s
    out[:3, 3] = -(R.T @ T[:3, 3]) / s
    return out


def compose(*Ts: np.ndarray) -> np.ndarray:
    """Chain transforms left to right: ``compose(T_a_b, T_b_c) == T_a_c``."""
    out = np.eye(4)
    for T in Ts:
        out = out @ np.asarray(T, dtype=np.float64)
    return out


def apply_T(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Map (N, 3) points through a (4, 4) transform: ``p_a = T_a_b @ p_b``. NaN rows stay NaN."""
    T = np.asarray(T, dtype=np.float64)
    out = _rotate(_as_points(points), T[:3, :3])
    out += T[:3, 3]
    return out


def cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N, 3) float64 row-wise cross products of ``a`` and ``b`` ((N, 3) each, or one of them (3,)): the same bits
    as ``np.cross(a, b)`` (the same products and differences, in the same order) at a third of its CPU on
    200k rows (``np.cross`` moves axes and allocates a temporary per term; issue 51, the truth evaluation)."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    np.multiply(a1, b2, out=out[..., 0])
    out[..., 0] -= a2 * b1
    np.multiply(a2, b0, out=out[..., 1])
    out[..., 1] -= a0 * b2
    np.multiply(a0, b1, out=out[..., 2])
    out[..., 2] -= a1 * b0
    return out


def transform_vectors(T: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """Rotate (N, 3) direction vectors (normals, ray directions) by the rotation of a rigid ``T``."""
    T = np.asarray(T, dtype=np.float64)
    A = T[:3, :3]
    return _rotate(_as_points(vectors, "vectors"), A / _scale_of(A))


def _rotate(P: np.ndarray, A: np.ndarray) -> np.ndarray:
    """(N, 3) rows of ``P`` times ``A.T``, through BLAS: as ``apply_T`` on 1.3M rows 13.8 CPU-ms on one
    BLAS thread against 47 for numpy's einsum loop (``benchmarks/app/bench_process_parts.py``; see
    rangekit._runtime.threads for the thread count)."""
    return P @ A.T


def rotvec_to_R(rotvec: np.ndarray) -> np.ndarray:
    """Rotation vector (axis * angle, radians) to a (3, 3) rotation matrix."""
    from scipy.spatial.transform import Rotation  # scipy.spatial takes 0.6 s to import

    return Rotation.from_rotvec(np.asarray(rotvec, dtype=np.float64)).as_matrix()


def R_to_rotvec(R: np.ndarray) -> np.ndarray:
    """(3, 3) rotation matrix to rotation vector (axis * angle, radians, angle in [0, pi])."""
    from scipy.spatial.transform import Rotation  # scipy.spatial takes 0.6 s to import

    return Rotation.from_matrix(np.asarray(R, dtype=np.float64)).as_rotvec()


def quat_to_R(quat_xyzw: np.ndarray) -> np.ndarray:
    """Unit quaternion, scalar last ``(x, y, z, w)``, to a (3, 3) rotation matrix."""
    from scipy.spatial.transform import Rotation  # scipy.spatial takes 0.6 s to import

    return Rotation.from_quat(np.asarray(quat_xyzw, dtype=np.float64)).as_matrix()


def R_to_quat(R: np.ndarray) -> np.ndarray:
    """(3, 3) rotation matrix to a unit quaternion ``(x, y, z, w)`` with ``w >= 0``."""
    from scipy.spatial.transform import Rotation  # scipy.spatial takes 0.6 s to import

    q = Rotation.from_matrix(np.asarray(R, dtype=np.float64)).as_quat()
    return q if q[3] >= 0 else -q


def axis_angle_to_R(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation by ``angle`` radians about ``axis`` (any non-zero length), right-hand rule."""
    axis = np.asarray(axis, dtype=np.float64).reshape(3)
    n = np.linalg.norm(axis)
    if n == 0:
        raise InputError("axis_angle_to_R: the axis is the zero vector; give a direction such as (0, 0, 1)")
    return rotvec_to_R(axis / n * angle)


def R_up_to_z(up) -> np.ndarray:
    """(3, 3) rotation that turns direction ``up`` (3,) (any non-zero length) onto +z: the shortest one,
    about ``up x z``; ``up`` = -z gives the half turn about x. The one rule that stands a mesh upright
    (``rangekit scan --up``, the simulator's Stanford bunny: ``up`` = +y gives y -> z, z -> -y)."""
    u = np.asarray(up, dtype=np.float64)
    if u.shape != (3,) or not np.all(np.isfinite(u)) or np.linalg.norm(u) == 0:
        raise InputError(f"up: expected a finite non-zero direction (x, y, z), found {up!r}")
    u = u / np.linalg.norm(u)
    axis = np.cross(u, [0.0, 0.0, 1.0])
    if np.linalg.norm(axis) <= 1e-12:
        return np.eye(3) if u[2] > 0 else np.diag([1.0, -1.0, -1.0])
    return axis_angle_to_R(axis, float(np.arctan2(np.linalg.norm(axis), u[2])))


def nearest_rotation(M: np.ndarray) -> np.ndarray:
    """The rotation closest to ``M`` in the Frobenius norm (SVD projection onto SO(3), det = +1)."""
    U, _, Vt = np.linalg.svd(np.asarray(M, dtype=np.float64))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    return U @ D @ Vt


def rotation_angle(R: np.ndarray) -> float:
    """Angle of a rotation in radians, in [0, pi]; accurate for small angles too."""
    return float(np.linalg.norm(R_to_rotvec(nearest_rotation(R))))


def rigid_problem(T, *, tol: float = 1e-9) -> str | None:
    """Why ``T`` is not a rigid transform ``[[R, t], [0, 0, 0, 1]]`` (finite, R orthonormal to ``tol``,
    det R = +1), or None when it is one. The one rigid-transform check of rig files, cameras and poses."""
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4):
        return f"shape {T.shape}, expected (4, 4)"
    if not np.all(np.isfinite(T)):
        return "non-finite entries"
    R = T[:3, :3]
    if np.abs(R).max() > 2.0:  # a rotation's entries are in [-1, 1]; also keeps R @ R.T from overflowing
        return f"entries of R up to {np.abs(R).max():.3g} (a rotation's are in [-1, 1])"
    off = float(np.abs(R @ R.T - np.eye(3)).max())
    if off > tol:
        return f"max |R R^T - I| = {off:.2g} (more than {tol:g})"
    if np.linalg.det(R) < 0:
        return f"det R = {np.linalg.det(R):.6g} (a reflection)"
    if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], rtol=0.0, atol=1e-12):
        return f"last row {T[3].tolist()}, expected [0, 0, 0, 1]"
    return None


def ray_plane_t(origins: np.ndarray, directions: np.ndarray, planes: np.ndarray) -> np.ndarray:
    """Ray parameter t where each ray ``o + t d`` meets its plane ``n . X + d = 0`` (Fusiello eq. 13.7 in
    world form): ``t = -(n . o + d) / (n . d)``.

    Parameters
    ----------
    origins, directions : (N, 3) float64 (directions need not be unit; t is in their units).
    planes : (4,) one plane for every ray, or (N, 4) one per ray; ``[n, d]``.

    Returns
    -------
    (N,) float64; +-inf or NaN where a ray is parallel to its plane. The caller decides what to refuse
    (points behind the origin: t <= 0; grazing rays: small |n . d|).
    """
    planes = np.asarray(planes, dtype=np.float64)
    n, d = planes[..., :3], planes[..., 3]
    denom = np.einsum("...j,...j->...", n, directions)
    with np.errstate(divide="ignore", invalid="ignore"):
        return -(np.einsum("...j,...j->...", n, origins) + d) / denom


def look_at(eye: np.ndarray, target: np.ndarray, up: np.ndarray = (0.0, 0.0, 1.0)) -> np.ndarray:
    """Pose ``T_world_cam`` of an OpenCV camera (x right, y down, z forward) at ``eye`` looking at ``target``.

    ``up`` is the world direction that appears up in the image (so image y points along ``-up``).
    """
    eye = np.asarray(eye, dtype=np.float64)
    z = np.asarray(target, dtype=np.float64) - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, np.asarray(up, dtype=np.float64))
    if np.linalg.norm(x) < 1e-12:
        raise InputError("look_at: the viewing direction is parallel to 'up'; choose another up vector")
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return make_T(np.column_stack([x, y, z]), eye)


@dataclass(frozen=True)
class ProcrustesResult:
    """Absolute orientation: ``dst ~= scale * R @ src + t``."""

    T_dst_src: np.ndarray  # (4, 4) float64 similarity (rigid when scale == 1); p_dst = T_dst_src @ p_src
    scale: float           # isotropic scale s; 1.0 for a rigid fit
    rmse: float            # weighted RMS of the residual distances in input units; lower is better
    residuals: np.ndarray  # (N,) float64 distances |dst_i - T src_i|

    @property
    def R(self) -> np.ndarray:
        return self.T_dst_src[:3, :3] / self.scale

    @property
    def t(self) -> np.ndarray:
        return self.T_dst_src[:3, 3].copy()

    def __repr__(self) -> str:
        angle = np.degrees(rotation_angle(self.R))
        return (f"ProcrustesResult(angle={angle:.6f} deg, t={np.round(self.t, 6).tolist()}, "
                f"scale={self.scale:.9f}, rmse={self.rmse:.3e})")


def procrustes(src: np.ndarray, dst: np.ndarray, *, weights: np.ndarray | None = None,
               scale: bool = False) -> ProcrustesResult:
    """Absolute orientation by orthogonal Procrustes analysis (Fusiello ch. 15; Umeyama 1991).

    Minimises ``sum_i w_i |dst_i - (s R src_i + t)|^2`` over rotations R (det = +1), translations t and,
    when ``scale`` is True, a scale s > 0.

    Parameters
    ----------
    src, dst : (N, 3) array_like
        Corresponding points, N >= 3 not all collinear (any units; the result uses the same).
    weights : (N,) array_like, optional
        Non-negative weight per correspondence (e.g. 0 for a missing one). Default: all 1.
    scale : bool, optional
        Also estimate an isotropic scale (similarity). Default False (rigid).

    Returns
    -------
    ProcrustesResult

    Raises
    ------
    InputError
        If the shapes differ, fewer than 3 points have positive weight, weights are negative or NaN,
        or the points are degenerate (collinear) so the rotation is not determined.
    """
    P = _as_points(src, "src")
    Q = _as_points(dst, "dst")
    if P.shape != Q.shape:
        raise InputError(f"procrustes: src has shape {P.shape}, dst has shape {Q.shape}; they must match")
    w = np.ones(len(P)) if weights is None else np.asarray(weights, dtype=np.float64).reshape(-1)
    if w.shape[0] != len(P):
        raise InputError(f"procrustes: {w.shape[0]} weights for {len(P)} points")
    if not np.all(np.isfinite(w)) or np.any(w < 0):
        raise InputError("procrustes: weights must be finite and non-negative")
    if np.count_nonzero(w) < 3:
        raise InputError(f"procrustes: needs at least 3 points with positive weight, found {np.count_nonzero(w)}")
    if not (np.all(np.isfinite(P[w > 0])) and np.all(np.isfinite(Q[w > 0]))):
        raise InputError("procrustes: src or dst has NaN/inf rows with positive weight; "
                         "drop them or give them weight 0")
    keep = w > 0
    P, Q, w = P[keep], Q[keep], w[keep]
    wn = w / w.sum()
    mu_p = wn @ P
    mu_q = wn @ Q
    Pc = P - mu_p
    Qc = Q - mu_q
    # Cross-covariance, then R = U diag(1, 1, det(U V^T)) V^T (Umeyama eq. 39-40).
    S = (Qc * wn[:, None]).T @ Pc
    U, sing, Vt = np.linalg.svd(S)
    if sing[1] < 1e-12 * max(sing[0], 1e-300):
        raise InputError("procrustes: the points are collinear (or coincident), so the rotation is not "
                         "determined; give at least 3 non-collinear correspondences")
    d = np.sign(np.linalg.det(U @ Vt))
    D = np.array([1.0, 1.0, d if d != 0 else 1.0])
    R = U @ np.diag(D) @ Vt
    if scale:
        var_p = float(wn @ np.sum(Pc * Pc, axis=1))
        s = float((sing * D).sum() / var_p)  # Umeyama eq. 42
    else:
        s = 1.0
    t = mu_q - s * R @ mu_p
    T = make_T(R, t, scale=s)
    # Residuals over all input rows (NaN for dropped/invalid rows).
    P_all = _as_points(src, "src")
    Q_all = _as_points(dst, "dst")
    res = np.linalg.norm(Q_all - apply_T(T, P_all), axis=1)
    w_all = np.ones(len(P_all)) if weights is None else np.asarray(weights, dtype=np.float64).reshape(-1)
    good = w_all > 0
    rmse = float(np.sqrt(np.sum(w_all[good] * res[good] ** 2) / np.sum(w_all[good])))
    return ProcrustesResult(T_dst_src=T, scale=s, rmse=rmse, residuals=res)
