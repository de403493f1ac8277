"""The pinhole model with OpenCV lens distortion, for cameras and projectors alike.

A projector is an inverse camera: the same intrinsics map a ray to the projector pixel it comes from.
Frames and units: world points in metres; camera frame x right, y down, z forward (OpenCV); pixels
``(u, v) = (column, row)`` with the centre of the top-left pixel at (0, 0). ``T_world_cam`` maps camera
coordinates to world coordinates (for a projector it is the projector's pose).

Distortion follows OpenCV exactly (``cv2.projectPoints``): coefficients ``(k1, k2, p1, p2[, k3[, k4, k5,
k6[, s1, s2, s3, s4[, tx, ty]]]])``; the tilted-sensor terms tx, ty must be zero.
"""

from __future__ import annotations

import json
import threading
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rangekit.errors import ConfigError, InputError
from rangekit._runtime.memory import forgettable_cache
from rangekit.geometry import apply_T, invert_T, rigid_problem, transform_vectors
from rangekit.lens import distort, distort_jacobian, undistort

__all__ = ["PinholeCamera", "distort", "distort_jacobian", "forget_pixel_rays", "undistort", "pixel_rays",
           "world_pixel_rays"]

def _matrix(value, shape: tuple[int, ...], name: str, where: str) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f"{where}: field {name!r} must be a numeric array of shape {shape}") from exc
    if arr.shape != shape or not np.all(np.isfinite(arr)):
        raise ConfigError(f"{where}: field {name!r} must be a finite array of shape {shape}, "
                          f"found shape {arr.shape}")
    return arr


@dataclass(frozen=True, eq=False)
class PinholeCamera:
    """A calibrated camera or projector.

    Attributes
    ----------
    K : (3, 3) float64 intrinsic matrix in pixels (fx, fy, cx, cy; zero skew, as OpenCV).
    dist : (M,) float64 OpenCV distortion coefficients, M in {0, 4, 5, 8, 12, 14}.
    width, height : int, image size in pixels (for a projector, its native resolution).
    T_world_cam : (4, 4) float64 rigid pose, ``p_world = T_world_cam @ p_cam``.
    name : str, a label used in messages and rig files.
    """

    K: np.ndarray
    width: int
    height: int
    dist: np.ndarray = field(default_factory=lambda: np.zeros(5))
    T_world_cam: np.ndarray = field(default_factory=lambda: np.eye(4))
    name: str = "camera"

    def __post_init__(self) -> None:
        where = f"camera {self.name!r}"
        K = _matrix(self.K, (3, 3), "K", where)
        if K[0, 0] <= 0 or K[1, 1] <= 0 or K[2, 2] != 1 or np.any(K[2, :2] != 0) or K[1, 0] != 0 \
                or K[0, 1] != 0:
            raise ConfigError(f"{where}: K must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] with fx, fy > 0 and no "
                              f"skew (as in OpenCV), found {K.tolist()}")
        dist = np.asarray(self.dist, dtype=np.float64).reshape(-1)
        if dist.size not in (0, 4, 5, 8, 12, 14) or not np.all(np.isfinite(dist)):
            raise ConfigError(f"{where}: 'dist' must hold 4, 5, 8, 12 or 14 finite OpenCV coefficients, "
                              f"found {dist.size}")
        if dist.size == 14 and np.any(dist[12:] != 0):
            raise ConfigError(f"{where}: tilted-sensor distortion (tx, ty = {dist[12:].tolist()}) is not "
                              "supported; recalibrate without CALIB_TILTED_MODEL")
        T = _matrix(self.T_world_cam, (4, 4), "T_world_cam", where)
        problem = rigid_problem(T, tol=1e-9)
        if problem is not None:
            raise ConfigError(f"{where}: 'T_world_cam' must be a rigid transform (orthonormal rotation, "
                              f"det +1, last row 0 0 0 1); found {problem}")
        if int(self.width) <= 0 or int(self.height) <= 0:
            raise ConfigError(f"{where}: width and height must be positive, found {self.width}x{self.height}")
        object.__setattr__(self, "K", K)
        object.__setattr__(self, "dist", dist)
        object.__setattr__(self, "T_world_cam", T)
        object.__setattr__(self, "width", int(self.width))
        object.__setattr__(self, "height", int(self.height))
        for arr in (K, dist, T):
            arr.flags.writeable = False

    @property
    def size(self) -> tuple[int, int]:
        """(width, height) in pixels."""
        return self.width, self.height

    @property
    def center(self) -> np.ndarray:
        """(3,) optical centre in world coordinates, metres."""
        return self.T_world_cam[:3, 3].copy()

    @property
    def T_cam_world(self) -> np.ndarray:
        return invert_T(self.T_world_cam)

    def with_pose(self, T_world_cam: np.ndarray) -> "PinholeCamera":
        """A copy with another pose."""
        return PinholeCamera(self.K, self.width, self.height, self.dist, T_world_cam, self.name)

    def resized(self, width: int, height: int) -> "PinholeCamera":
        """The same lens on a sensor of another resolution (same field of view; pixel centres kept)."""
        sx, sy = width / self.width, height / self.height
        K = self.K.copy()
        K[0, :] *= sx
        K[1, :] *= sy
        K[0, 2] = (self.K[0, 2] + 0.5) * sx - 0.5
        K[1, 2] = (self.K[1, 2] + 0.5) * sy - 0.5
        return PinholeCamera(K, width, height, self.dist, self.T_world_cam, self.name)

    def pixel_grid(self) -> np.ndarray:
        """(H * W, 2) float64 centres of every pixel, row-major (row 0 first)."""
        v, u = np.mgrid[0: self.height, 0: self.width]
        return np.column_stack([u.ravel(), v.ravel()]).astype(np.float64)

    def normalized_to_pixels(self, xy: np.ndarray) -> np.ndarray:
        """(N, 2) undistorted normalised coordinates -> (N, 2) pixels (applies distortion and K)."""
        xd = distort(np.asarray(xy, dtype=np.float64), self.dist)
        K = self.K
        u = K[0, 0] * xd[:, 0] + K[0, 2]
        v = K[1, 1] * xd[:, 1] + K[1, 2]
        return np.column_stack([u, v])

    def pixels_to_normalized(self, uv: np.ndarray) -> np.ndarray:
        """(N, 2) pixels -> (N, 2) undistorted normalised coordinates (exact inverse of the lens model)."""
        uv = np.asarray(uv, dtype=np.float64)
        if uv.ndim != 2 or uv.shape[1] != 2:
            raise InputError(f"{self.name}: pixels must be an (N, 2) array of (u, v), found shape {uv.shape}")
        K = self.K
        yd = (uv[:, 1] - K[1, 2]) / K[1, 1]
        xd = (uv[:, 0] - K[0, 2]) / K[0, 0]
        return undistort(np.column_stack([xd, yd]), self.dist)

    def project_cam(self, points_cam: np.ndarray) -> np.ndarray:
        """(N, 3) points in this device's frame -> (N, 2) pixels; NaN where z <= 0."""
        P = np.asarray(points_cam, dtype=np.float64)
        z = P[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = P[:, :2] / z[:, None]
        xy[~(z > 0)] = np.nan
        return self.normalized_to_pixels(xy)

    def project(self, points_world: np.ndarray) -> np.ndarray:
        """(N, 3) world points (metres) -> (N, 2) pixels ``(u, v)``; NaN for points behind the device.

        Pixels may fall outside the image; compare with ``width``/``height`` to test visibility.
        """
        return self.project_cam(apply_T(self.T_cam_world, points_world))

    def rays(self, uv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Back-project (N, 2) pixels ``uv`` (u = column, v = row; distorted, as seen in the image) to world
        rays: ``origins`` (N, 3) float64, the optical centre in world coordinates (metres), and ``directions``
        (N, 3) float64 unit vectors in world coordinates, NaN where the lens model could not be inverted."""
        return self.rays_from_normalized(self.pixels_to_normalized(uv))

    def rays_from_normalized(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`rays` from (N, 2) undistorted normalised coordinates (:meth:`pixels_to_normalized`)."""
        d_world = self.directions_from_normalized(xy)
        return np.broadcast_to(self.center, d_world.shape).copy(), d_world

    def directions_from_normalized(self, xy: np.ndarray) -> np.ndarray:
        """The (N, 3) world unit directions of :meth:`rays_from_normalized`, without the (N, 3) origins."""
        d = np.column_stack([xy, np.ones(len(xy))])
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        return transform_vectors(self.T_world_cam, d)

    def column_planes(self, cols: np.ndarray | None = None, *, rows: np.ndarray | None = None,
                      n_samples: int = 65) -> np.ndarray:
        """World planes of projector columns, as (N, 4) ``[n, d]`` with ``n . X + d = 0``, |n| = 1.

        The light a projector sends through column ``u`` is the fan of rays through ``(u, v)`` for every
        row v. Without distortion that fan is exactly a plane through the optical centre. With
        distortion it is a slightly curved surface through the centre, and this returns:

        - ``rows`` is None: the least-squares plane through the centre that best fits the ray directions
          sampled at ``n_samples`` rows evenly spread over the image (the smallest eigenvector of their
          scatter matrix). Exact without distortion; with distortion the rays deviate from it by the
          curvature of the column (see docs/camera.md for figures on the default rig).
        - ``rows`` given (same length as ``cols``): the plane tangent to the light surface at
          ``(u, v)``: it contains the ray through ``(u, v)`` exactly and the surface's direction along
          the column there, so it is exact for points lit near that row (use it with a decoded row).

        Normals point towards increasing column numbers. ``cols`` default: every column 0..width-1.
        """
        cols = np.arange(self.width, dtype=np.float64) if cols is None else \
            np.asarray(cols, dtype=np.float64).reshape(-1)
        R = self.T_world_cam[:3, :3]
        if rows is None:
            v = np.linspace(-0.5, self.height - 0.5, n_samples)
            uv = np.column_stack([np.repeat(cols, n_samples), np.tile(v, cols.size)])
            xy = self.pixels_to_normalized(uv)
            D = np.concatenate([xy, np.ones((len(xy), 1))], axis=1)
            D /= np.linalg.norm(D, axis=1, keepdims=True)
            D = D.reshape(cols.size, n_samples, 3)
            M = np.einsum("nsi,nsj->nij", D, D)
            _, vecs = np.linalg.eigh(M)
            n_cam = vecs[:, :, 0]
        else:
            rows = np.asarray(rows, dtype=np.float64).reshape(-1)
            if rows.shape != cols.shape:
                raise InputError(f"{self.name}: column_planes got {cols.size} cols and {rows.size} rows")
            h = 0.5
            xy = self.pixels_to_normalized(np.column_stack([np.r_[cols, cols, cols],
                                                            np.r_[rows, rows - h, rows + h]]))
            D = np.concatenate([xy, np.ones((len(xy), 1))], axis=1).reshape(3, cols.size, 3)
            n_cam = np.cross(D[0], D[2] - D[1])
            n_cam /= np.linalg.norm(n_cam, axis=1, keepdims=True)
        # Orient towards increasing u: compare with the direction of the neighbouring column.
        xy_next = self.pixels_to_normalized(np.column_stack([cols + 1.0, np.full(cols.size, self.height / 2)]))
        probe = np.concatenate([xy_next, np.ones((cols.size, 1))], axis=1)
        sign = np.sign(np.sum(n_cam * probe, axis=1))
        sign[sign == 0] = 1.0
        n_cam *= sign[:, None]
        n_world = n_cam @ R.T
        d = -n_world @ self.center
        return np.column_stack([n_world, d])

    def to_dict(self) -> dict:
        """A JSON-ready dict (lists of floats), the rig-file form of this device."""
        return {
            "name": self.name,
            "width": self.width,
            "height": self.height,
            "K": self.K.tolist(),
            "dist": self.dist.tolist(),
            "T_world_cam": self.T_world_cam.tolist(),
        }

    @classmethod
    def from_dict(cls, data: dict, *, where: str = "camera") -> "PinholeCamera":
        """Inverse of :meth:`to_dict`; ``where`` names the source (file and key) in error messages."""
        if not isinstance(data, dict):
            raise ConfigError(f"{where}: expected an object with K, dist, width, height, T_world_cam, "
                              f"found {type(data).__name__}")
        missing = [k for k in ("K", "width", "height") if k not in data]
        if missing:
            raise ConfigError(f"{where}: missing field(s) {missing}")
        try:
            width, height = int(data["width"]), int(data["height"])
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"{where}: 'width' and 'height' must be integers, found "
                              f"{data['width']!r}, {data['height']!r}") from exc
        try:
            return cls(K=data["K"], width=width, height=height, dist=data.get("dist", []),
                       T_world_cam=data.get("T_world_cam", np.eye(4).tolist()),
                       name=str(data.get("name", where)))
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from exc

    def save(self, path: str | Path) -> None:
        """Write the camera as JSON (:meth:`to_dict`), atomically: a crash leaves the old file or the new one."""
        from rangekit.io import atomic_write_json  # imported here: rangekit.io loads OpenCV

        atomic_write_json(path, self.to_dict())

    @classmethod
    def load(cls, path: str | Path) -> "PinholeCamera":
        try:
            data = json.loads(Path(path).read_text())
        except (OSError, json.JSONDecodeError) as exc:
            raise ConfigError(f"{path}: cannot read camera JSON: {exc}") from exc
        return cls.from_dict(data, where=str(path))

    def __repr__(self) -> str:
        K = self.K
        return (f"PinholeCamera(name={self.name!r}, {self.width}x{self.height}, fx={K[0, 0]:.2f}, "
                f"fy={K[1, 1]:.2f}, cx={K[0, 2]:.2f}, cy={K[1, 2]:.2f}, dist={np.round(self.dist, 5).tolist()}, "
                f"centre={np.round(self.center, 4).tolist()} m)")


_RAY_CACHE: dict[bytes, np.ndarray] = {}
_RAY_LOCK = threading.Lock()


def pixel_rays(camera: PinholeCamera) -> np.ndarray:
    """Unit ray directions of every pixel centre, in the camera's own frame (lens distortion undone):
    (H, W, 3) float64, read-only: ``d[v, u]`` is the unit direction (x right, y down, z forward) of the
    ray through pixel centre ``(u, v)``; NaN where the lens model cannot be inverted. The world-frame
    rays are ``transform_vectors(camera.T_world_cam, d.reshape(-1, 3))`` from ``camera.center``, bit for
    bit what ``camera.rays(camera.pixel_grid())`` returns.

    Depends only on the lens (K, dist, size), not on the pose, and is cached (with the world rays, the last
    eight): undoing the distortion of every pixel is costly, and a lens does not change between views."""
    key = _lens_key(camera)
    d = _RAY_CACHE.get(key)
    if d is None:
        xy = camera.pixels_to_normalized(camera.pixel_grid())
        d = np.column_stack([xy, np.ones(len(xy))])
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        d = _cache_rays(key, d.reshape(camera.height, camera.width, 3))
    return d


def world_pixel_rays(camera: PinholeCamera) -> tuple[np.ndarray, np.ndarray]:
    """World rays of every pixel centre, row by row: ``(origins, directions)``, (H * W, 3) float64 each (the
    optical centre; unit vectors, NaN where the lens cannot be inverted), as ``camera.rays(camera.pixel_grid())``.
    Both read-only: the directions cached per lens and pose (a turntable scan's views share the pose), the
    origins the centre broadcast to every row (no memory: most callers read only the directions)."""
    key = b"world" + camera.T_world_cam.tobytes() + _lens_key(camera)
    d = _RAY_CACHE.get(key)
    if d is None:
        d = _cache_rays(key, transform_vectors(camera.T_world_cam, pixel_rays(camera).reshape(-1, 3)))
    return np.broadcast_to(camera.center, d.shape), d


def _lens_key(camera: PinholeCamera) -> bytes:
    return np.concatenate([camera.K.ravel(), camera.dist.ravel(), [camera.dist.size, *camera.size]]).tobytes()


@forgettable_cache
def forget_pixel_rays() -> None:
    """Drop the cached rays (63 MB at 1280x1024): processing's views are decoded and measured. Safe beside
    threads that read them (each keeps the array it was given)."""
    with _RAY_LOCK:
        _RAY_CACHE.clear()


def _cache_rays(key: bytes, d: np.ndarray) -> np.ndarray:
    """``d``, read-only, kept under ``key``; the oldest of eight goes."""
    d.flags.writeable = False
    with _RAY_LOCK:
        if len(_RAY_CACHE) >= 8:
            _RAY_CACHE.pop(next(iter(_RAY_CACHE)))
        _RAY_CACHE[key] = d
    return d
