"""The simulator's object type: a triangle mesh with per-vertex albedo, optional planar texture and
specularity, in its own frame with a pose (metres). Builders are in :mod:`rangekit.sim.scene.objects`."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import trimesh

from rangekit.errors import SceneError
from rangekit.geometry import apply_T, axis_angle_to_R

__all__ = ["PlanarTexture", "SceneObject"]


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.flags.writeable = False
    return a


def _unit(n: np.ndarray) -> np.ndarray:
    norm = np.linalg.norm(n, axis=1, keepdims=True)
    return _readonly(np.divide(n, norm, out=np.zeros_like(n), where=norm > 0))


@dataclass(frozen=True, eq=False, repr=False)
class PlanarTexture:
    """A grey albedo image printed on an object's own z = 0 plane (arrays stored read-only).

    ``image`` (h, w) float32 albedo in [0, 1]; ``extent`` (x0, y0, x1, y1) metres in the object frame:
    image row r, column c covers x in ``[x0 + c * tx, x0 + (c + 1) * tx]``, y in ``[y0 + r * ty, ...]`` with
    texel sizes ``tx = (x1 - x0) / w``, ``ty = (y1 - y0) / h``. The texture replaces the vertex albedo where
    a camera ray meets the object on its z = 0 plane from the front (the side its triangles face); seen
    from behind, the object keeps its vertex albedo. Outside the extent the vertex albedo applies too.
    """

    image: np.ndarray
    extent: tuple[float, float, float, float]

    def __post_init__(self) -> None:
        img = np.asarray(self.image)
        if img.ndim != 2 or img.shape[0] < 1 or img.shape[1] < 1 or not np.issubdtype(img.dtype, np.floating):
            raise SceneError(f"PlanarTexture: image must be an (h, w) float albedo array, found shape "
                             f"{img.shape} dtype {img.dtype}")
        img = img.astype(np.float32)
        if not (np.all(np.isfinite(img)) and img.min() >= 0 and img.max() <= 1):
            raise SceneError(f"PlanarTexture: albedo must be finite and in [0, 1], found "
                             f"[{np.nanmin(img)}, {np.nanmax(img)}]")
        ext = tuple(float(e) for e in np.asarray(self.extent, dtype=np.float64).reshape(-1))
        if len(ext) != 4 or not np.all(np.isfinite(ext)) or not (ext[2] > ext[0] and ext[3] > ext[1]):
            raise SceneError(f"PlanarTexture: extent must be finite (x0, y0, x1, y1) with x1 > x0 and y1 > y0 "
                             f"(metres), found {self.extent!r}")
        object.__setattr__(self, "image", _readonly(img))
        object.__setattr__(self, "extent", ext)

    def __repr__(self) -> str:
        h, w = self.image.shape
        return f"PlanarTexture({w}x{h} texels, extent_m={tuple(round(e, 6) for e in self.extent)})"

    @property
    def texel(self) -> tuple[float, float]:
        """(tx, ty) texel size in metres along object x and y."""
        h, w = self.image.shape
        x0, y0, x1, y1 = self.extent
        return (x1 - x0) / w, (y1 - y0) / h

    @cached_property
    def summed_area(self) -> np.ndarray:
        """(h + 1, w + 1) float64 integral image: ``S[r, c] = image[:r, :c].sum()`` (texel units).

        Bilinear interpolation of S at fractional texel coordinates is the exact integral of the
        piecewise-constant texture over ``[0, X] x [0, Y]``.
        """
        h, w = self.image.shape
        S = np.zeros((h + 1, w + 1))
        np.cumsum(self.image, axis=0, dtype=np.float64, out=S[1:, 1:])
        np.cumsum(S[1:, 1:], axis=1, out=S[1:, 1:])
        S.flags.writeable = False
        return S

    def box_mean(self, x0: np.ndarray, y0: np.ndarray, x1: np.ndarray, y1: np.ndarray) -> np.ndarray:
        """(N,) mean albedo over the object-frame boxes ``[x0, x1] x [y0, y1]`` (metres), clipped to the extent.

        Exact area average (partial texels count by their covered area). A box that is empty after
        clipping (or degenerate) gives the texel at its clipped centre.
        """
        h, w = self.image.shape
        ex0, ey0, _, _ = self.extent
        tx, ty = self.texel
        X0, X1 = np.clip((np.asarray(x0) - ex0) / tx, 0, w), np.clip((np.asarray(x1) - ex0) / tx, 0, w)
        Y0, Y1 = np.clip((np.asarray(y0) - ey0) / ty, 0, h), np.clip((np.asarray(y1) - ey0) / ty, 0, h)
        area = (X1 - X0) * (Y1 - Y0)
        F = self._integral
        with np.errstate(divide="ignore", invalid="ignore"):
            mean = (F(X1, Y1) - F(X0, Y1) - F(X1, Y0) + F(X0, Y0)) / area
        small = ~(area > 1e-9)
        if np.any(small):
            c = np.clip(np.floor((X0[small] + X1[small]) / 2), 0, w - 1).astype(np.int64)
            r = np.clip(np.floor((Y0[small] + Y1[small]) / 2), 0, h - 1).astype(np.int64)
            mean[small] = self.image[r, c]
        return np.clip(mean, 0.0, 1.0)

    def _integral(self, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
        """Integral of the texture over [0, X] x [0, Y] (texel units): bilinear in the summed-area table."""
        S = self.summed_area.ravel()
        h, w = self.image.shape
        c = np.minimum(X.astype(np.int64), w - 1)  # X >= 0, so truncation is floor
        r = np.minimum(Y.astype(np.int64), h - 1)
        fx, fy = X - c, Y - r
        i = r * (w + 1) + c
        top = S.take(i) + fx * (S.take(i + 1) - S.take(i))
        bottom = S.take(i + w + 1) + fx * (S.take(i + w + 2) - S.take(i + w + 1))
        return top + fy * (bottom - top)


@dataclass(frozen=True, eq=False, repr=False)
class SceneObject:
    """A rigid triangle mesh in a simulated scene (arrays stored as read-only copies).

    Invalid input raises :class:`SceneError` naming the object, the expected and the found value.
    """

    name: str
    vertices: np.ndarray        # (V, 3) float64, object frame, metres
    triangles: np.ndarray       # (F, 3) int64, counter-clockwise seen from outside (outward normals)
    vertex_albedo: np.ndarray   # (V, 3) linear RGB Lambertian albedo in [0, 1]; scalar or (3,) broadcast
    specular: float = 0.0       # Blinn-Phong specular coefficient k_s (0 = purely Lambertian)
    shininess: float = 50.0     # Blinn-Phong exponent
    T_world_obj: np.ndarray = field(default_factory=lambda: np.eye(4))  # rigid, p_world = T @ p_obj
    on_turntable: bool = True   # rotates with the turntable
    smooth: bool = True         # shade with interpolated vertex normals (False: flat facet normals)
    texture: PlanarTexture | None = None  # albedo printed on the object's z = 0 plane (front side only)

    def __post_init__(self) -> None:
        who = f"object {self.name!r}"
        try:
            V = np.asarray(self.vertices, dtype=np.float64)
            A = np.asarray(self.vertex_albedo, dtype=np.float64)
            T = np.asarray(self.T_world_obj, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise SceneError(f"{who}: vertices, albedo and pose must be numeric arrays ({exc})") from exc
        F = np.asarray(self.triangles)
        if V.ndim != 2 or V.shape[1] != 3 or len(V) < 3:
            raise SceneError(f"{who}: vertices must be a (V, 3) array with V >= 3, found shape {V.shape}")
        if not np.all(np.isfinite(V)):
            raise SceneError(f"{who}: {np.count_nonzero(~np.isfinite(V).all(1))} vertices are not finite")
        if F.ndim != 2 or F.shape[1] != 3 or len(F) < 1 or not (np.issubdtype(F.dtype, np.integer)):
            raise SceneError(f"{who}: triangles must be an (F, 3) integer array with F >= 1, "
                             f"found shape {F.shape} dtype {F.dtype}")
        if F.min() < 0 or F.max() >= len(V):
            raise SceneError(f"{who}: triangle indices must lie in [0, {len(V) - 1}], "
                             f"found [{F.min()}, {F.max()}]")
        if A.shape in ((), (3,)):
            A = np.broadcast_to(A, V.shape)
        if A.shape != V.shape:
            raise SceneError(f"{who}: vertex_albedo must be a scalar, (3,) or ({len(V)}, 3), found {A.shape}")
        if not (np.all(np.isfinite(A)) and A.min() >= 0.0 and A.max() <= 1.0):
            raise SceneError(f"{who}: albedo must lie in [0, 1], found [{np.nanmin(A)}, {np.nanmax(A)}]")
        if not (0.0 <= self.specular < np.inf and 0.0 < self.shininess < np.inf):
            raise SceneError(f"{who}: need specular >= 0 and shininess > 0, found specular="
                             f"{self.specular!r}, shininess={self.shininess!r}")
        if T.shape != (4, 4) or not np.all(np.isfinite(T)):
            raise SceneError(f"{who}: T_world_obj must be a finite (4, 4) array, found shape {T.shape}")
        R = T[:3, :3]
        if not (np.allclose(T[3], [0, 0, 0, 1]) and np.allclose(R.T @ R, np.eye(3), atol=1e-6)
                and np.linalg.det(R) > 0):
            raise SceneError(f"{who}: T_world_obj must be a rigid transform (rotation + translation), "
                             f"found rotation block with det {np.linalg.det(R):.6g}")
        if self.texture is not None and not isinstance(self.texture, PlanarTexture):
            raise SceneError(f"{who}: texture must be a PlanarTexture or None, found {type(self.texture).__name__}")
        for key, value in dict(vertices=_readonly(V), triangles=_readonly(F.astype(np.int64)),
                               vertex_albedo=_readonly(A), T_world_obj=_readonly(T),
                               specular=float(self.specular), shininess=float(self.shininess),
                               on_turntable=bool(self.on_turntable), smooth=bool(self.smooth)).items():
            object.__setattr__(self, key, value)

    def __repr__(self) -> str:
        ext = np.ptp(self.vertices, axis=0)
        return (f"SceneObject(name={self.name!r}, V={len(self.vertices)}, F={len(self.triangles)}, "
                f"extent_m=({ext[0]:.4g}, {ext[1]:.4g}, {ext[2]:.4g}), specular={self.specular:g}, "
                f"on_turntable={self.on_turntable}, smooth={self.smooth}"
                + (f", texture={self.texture!r})" if self.texture is not None else ")"))

    @cached_property
    def _face_cross(self) -> np.ndarray:
        v = self.vertices[self.triangles]  # (F, 3, 3)
        return np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])  # length = 2 * area

    @cached_property
    def _vertex_normals(self) -> np.ndarray:
        w = np.repeat(self._face_cross, 3, axis=0)  # area weights: one row per triangle corner
        V = len(self.vertices)
        return _unit(np.stack([np.bincount(self.triangles.ravel(), w[:, k], minlength=V) for k in range(3)], 1))

    def vertex_normals(self) -> np.ndarray:
        """(V, 3) unit area-weighted vertex normals, object frame (zero for unreferenced vertices)."""
        return self._vertex_normals

    def face_normals(self) -> np.ndarray:
        """(F, 3) unit facet normals, object frame (zero for degenerate triangles)."""
        return _unit(self._face_cross)

    def with_pose(self, T_world_obj: np.ndarray) -> SceneObject:
        """A copy with pose ``T_world_obj`` (4, 4), ``p_world = T_world_obj @ p_obj``."""
        return dataclasses.replace(self, T_world_obj=T_world_obj)

    def placed_on_table(self, xy: tuple[float, float] = (0.0, 0.0), yaw: float = 0.0) -> SceneObject:
        """A copy posed upright on the table top (world z = 0), replacing the current pose.

        The object's own z axis stays world z; it is rotated by ``yaw`` radians about world z around the
        centre of its object-frame x-y bounding box, that centre goes to ``xy`` (metres), and the lowest
        vertex lands exactly on z = 0.
        """
        lo, hi = self.vertices.min(axis=0), self.vertices.max(axis=0)
        c = np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, 0.0])
        T = np.eye(4)
        T[:3, :3] = axis_angle_to_R(np.array([0.0, 0.0, 1.0]), yaw)
        T[2, :3] = [0.0, 0.0, 1.0]  # exact, so that min z is exactly 0
        T[:3, 3] = np.array([xy[0], xy[1], -lo[2]]) - T[:3, :3] @ c
        return self.with_pose(T)

    def world_vertices(self) -> np.ndarray:
        """(V, 3) vertex positions in the world frame, metres."""
        return apply_T(self.T_world_obj, self.vertices)

    def to_trimesh(self) -> trimesh.Trimesh:
        """World-frame ``trimesh.Trimesh`` with 8-bit vertex colours from the albedo.

        Built with ``process=False``: vertex and face order are kept, so a ray hit's triangle index
        indexes ``triangles`` (duplicated vertices of boxes, caps and boards are not merged).
        """
        rgba = np.concatenate([np.round(self.vertex_albedo * 255), np.full((len(self.vertices), 1), 255)], 1)
        return trimesh.Trimesh(vertices=self.world_vertices(), faces=np.array(self.triangles),
                               vertex_colors=rgba.astype(np.uint8), process=False)
