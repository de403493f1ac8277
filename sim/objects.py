"""Procedurally built triangle-mesh objects for the simulated scanning rig.

Every builder returns a :class:`SceneObject` in its own natural frame (metres, pose identity) with
outward-facing (counter-clockwise seen from outside) triangles and a per-vertex linear RGB albedo.
Place it with :meth:`SceneObject.placed_on_table` or :meth:`SceneObject.with_pose`.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from functools import cached_property, lru_cache
from pathlib import Path
from typing import Callable

import numpy as np
import trimesh

from rangekit.boards import Board
from rangekit.errors import FileFormatError, InputError, SceneError
from rangekit.geometry import apply_T, axis_angle_to_R

__all__ = ["PlanarTexture", "SceneObject", "plane", "sphere", "box", "cylinder", "torus", "board_object",
           "calibration_board", "board_corners", "lumpy", "turntable_disc", "load_mesh", "BUILTIN_OBJECTS",
           "make_object"]


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


# --- builders ---------------------------------------------------------------------------------------

def _check(builder: str, **values: float) -> None:
    for key, value in values.items():
        if not (np.isfinite(value) and value > 0):
            raise SceneError(f"{builder}: {key} must be a finite number > 0, found {value!r}")


def _check_count(builder: str, key: str, value: int, minimum: int) -> None:
    if int(value) != value or value < minimum:
        raise SceneError(f"{builder}: {key} must be an integer >= {minimum}, found {value!r}")


def _grid_triangles(nu: int, nv: int, wrap_u: bool = False, wrap_v: bool = False) -> np.ndarray:
    """Triangles of a (nu, nv) vertex grid (index ``i * nv + j``), quads (i,j),(i+1,j),(i+1,j+1),(i,j+1).

    The diagonals alternate like a checkerboard, so every vertex gets equal triangle area on either
    side and area-weighted vertex normals are unbiased (e.g. exactly radial on a cylinder; with an odd
    wrapped count one seam keeps a small bias).
    """
    i, j = np.meshgrid(np.arange(nu if wrap_u else nu - 1), np.arange(nv if wrap_v else nv - 1), indexing="ij")
    i1, j1 = (i + 1) % nu, (j + 1) % nv
    a, b, c, d = i * nv + j, i1 * nv + j, i1 * nv + j1, i * nv + j1
    even = ((i + j) % 2 == 0)[..., None]
    t1 = np.where(even, np.stack([a, b, c], -1), np.stack([a, b, d], -1))
    t2 = np.where(even, np.stack([a, c, d], -1), np.stack([b, c, d], -1))
    return np.concatenate([t1.reshape(-1, 3), t2.reshape(-1, 3)], 0)


def _quad_soup(corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(Q, 4, 3) counter-clockwise quads -> (4Q, 3) vertices (own 4 per quad), (2Q, 3) triangles."""
    base = 4 * np.arange(len(corners))[:, None]
    tris = np.concatenate([base + [0, 1, 2], base + [0, 2, 3]], axis=1).reshape(-1, 3)
    return corners.reshape(-1, 3).astype(np.float64), tris


def plane(width: float = 0.4, height: float = 0.3, *, albedo=0.8, name: str = "plane",
          subdivisions: int = 1) -> SceneObject:
    """Rectangle ``width`` (x) by ``height`` (y) metres in z = 0, centred, normal +z, split into a
    ``subdivisions`` x ``subdivisions`` grid of quads. Flat shaded."""
    _check("plane", width=width, height=height)
    _check_count("plane", "subdivisions", subdivisions, 1)
    n = int(subdivisions) + 1
    x, y = np.meshgrid(np.linspace(-width / 2, width / 2, n), np.linspace(-height / 2, height / 2, n),
                       indexing="ij")
    verts = np.stack([x.ravel(), y.ravel(), np.zeros(n * n)], axis=1)
    return SceneObject(name, verts, _grid_triangles(n, n), albedo, smooth=False)


def sphere(radius: float = 0.05, *, subdivisions: int = 5, albedo=0.8, specular: float = 0.0,
           shininess: float = 50.0, name: str = "sphere") -> SceneObject:
    """Icosphere centred at the origin with every vertex exactly at ``radius`` (10 * 4**s + 2 vertices).

    The flat facets lie inside the true sphere; their largest distance to it (chordal error) is about
    ``0.21 * radius / 4**subdivisions``: for subdivisions=5 and radius=0.05 m it is 0.0142 mm, and the
    enclosed volume is 0.054 % below 4/3 pi r^3 (subdivisions=4: 0.057 mm; 6: 0.0036 mm).
    """
    _check("sphere", radius=radius)
    _check_count("sphere", "subdivisions", subdivisions, 0)
    m = trimesh.creation.icosphere(subdivisions=int(subdivisions), radius=1.0)
    v = np.asarray(m.vertices)
    v = radius * v / np.linalg.norm(v, axis=1, keepdims=True)
    return SceneObject(name, v, np.asarray(m.faces), albedo, specular, shininess)


def box(extents=(0.1, 0.08, 0.06), *, albedo=0.8, name: str = "box") -> SceneObject:
    """Closed box of ``extents`` (x, y, z) metres centred at the origin; 24 vertices (4 per face, not
    shared) so the vertex normals equal the face normals. Flat shaded."""
    h = np.asarray(extents, dtype=np.float64).reshape(3) / 2
    _check("box", **{f"extents[{k}]": float(2 * h[k]) for k in range(3)})
    quads = []
    for a in range(3):
        for s in (1.0, -1.0):
            u, v = ((a + 1) % 3, (a + 2) % 3) if s > 0 else ((a + 2) % 3, (a + 1) % 3)  # u x v = s * e_a
            q = np.zeros((4, 3))
            q[:, a] = s * h[a]
            q[:, u] = [-h[u], h[u], h[u], -h[u]]
            q[:, v] = [-h[v], -h[v], h[v], h[v]]
            quads.append(q)
    verts, tris = _quad_soup(np.array(quads))
    return SceneObject(name, verts, tris, albedo, smooth=False)


def cylinder(radius: float = 0.04, height: float = 0.1, *, sections: int = 128, albedo=0.8,
             specular: float = 0.0, shininess: float = 50.0, name: str = "cylinder") -> SceneObject:
    """Closed cylinder, axis z, centred at the origin. The side is smooth shaded; the cap rings are
    duplicated so the cap vertex normals are exactly +-z (flat caps, sharp rims)."""
    _check("cylinder", radius=radius, height=height)
    _check_count("cylinder", "sections", sections, 3)
    n = int(sections)
    t = 2 * np.pi * np.arange(n) / n
    ring = np.stack([radius * np.cos(t), radius * np.sin(t)], axis=1)
    z = np.full((n, 1), height / 2)
    side = np.stack([np.hstack([ring, -z]), np.hstack([ring, z])], axis=1).reshape(-1, 3)  # (k, bottom/top)
    verts = np.vstack([side, np.hstack([ring, z]), [[0, 0, height / 2]],
                       np.hstack([ring, -z]), [[0, 0, -height / 2]]])
    k = np.arange(n)
    top = np.stack([np.full(n, 3 * n), 2 * n + k, 2 * n + (k + 1) % n], axis=1)
    bottom = np.stack([np.full(n, 4 * n + 1), 3 * n + 1 + (k + 1) % n, 3 * n + 1 + k], axis=1)
    tris = np.vstack([_grid_triangles(n, 2, wrap_u=True), top, bottom])
    return SceneObject(name, verts, tris, albedo, specular, shininess)


def torus(major_radius: float = 0.06, minor_radius: float = 0.02, *, major_sections: int = 128,
          minor_sections: int = 64, albedo=0.8, specular: float = 0.0, shininess: float = 50.0,
          name: str = "torus") -> SceneObject:
    """Torus with axis z centred at the origin; vertices lie exactly on the true surface."""
    _check("torus", major_radius=major_radius, minor_radius=minor_radius)
    if minor_radius >= major_radius:
        raise SceneError(f"torus: minor_radius must be < major_radius, found {minor_radius} >= {major_radius}")
    _check_count("torus", "major_sections", major_sections, 3)
    _check_count("torus", "minor_sections", minor_sections, 3)
    nu, nv = int(major_sections), int(minor_sections)
    th, ph = np.meshgrid(2 * np.pi * np.arange(nu) / nu, 2 * np.pi * np.arange(nv) / nv, indexing="ij")
    rho = major_radius + minor_radius * np.cos(ph)
    verts = np.stack([rho * np.cos(th), rho * np.sin(th), minor_radius * np.sin(ph)], -1).reshape(-1, 3)
    return SceneObject(name, verts, _grid_triangles(nu, nv, True, True), albedo, specular, shininess)


def board_object(board: Board, *, name: str = "board", texel: float = 1e-4) -> SceneObject:
    """A flat calibration board: one quad over the board's texture extent, textured with ``board.texture``.

    Board frame as in :mod:`rangekit.boards`: z = 0 plane, corners at ``board.object_points()``, printed
    side facing -z (the triangles face -z, so the texture is seen from -z and the back is plain). Flat
    shaded; the vertex albedo is the texture's mean (what ``to_trimesh`` and views from behind show).
    ``texel`` (metres) must divide ``board.square``.
    """
    if not isinstance(board, Board):
        raise SceneError(f"board_object: board must be a rangekit.boards.Board, found {type(board).__name__}")
    try:
        tex = _board_texture(board, float(texel))
    except InputError as exc:
        raise SceneError(f"board_object({name!r}): {exc}") from exc
    x0, y0, x1, y1 = tex.extent
    verts = np.array([[x0, y0, 0.0], [x0, y1, 0.0], [x1, y1, 0.0], [x1, y0, 0.0]])  # counter-clockwise from -z
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    return SceneObject(name, verts, tris, float(tex.image.mean(dtype=np.float64)), smooth=False, texture=tex)


@lru_cache(maxsize=8)
def _board_texture(board: Board, texel: float) -> PlanarTexture:
    """One shared (immutable) texture per board, so a calibration run builds its summed-area table once."""
    return PlanarTexture(*board.texture(texel))


def board_corners(rows: int = 7, cols: int = 9, square: float = 0.02) -> np.ndarray:
    """(rows-1)*(cols-1), 3) inner-corner positions of :func:`calibration_board`, board frame, metres.

    Row-major, x fastest: corner ``i * (cols - 1) + j`` is at ``(j * square, i * square, 0)``, the order
    of OpenCV's ``findChessboardCorners(img, (cols - 1, rows - 1))`` object points. Same as
    ``Board(cols=cols, rows=rows, square=square).object_points()``.
    """
    j, i = np.meshgrid(np.arange(cols - 1), np.arange(rows - 1))
    return np.stack([j.ravel() * square, i.ravel() * square, np.zeros(j.size)], axis=1)


def calibration_board(rows: int = 7, cols: int = 9, square: float = 0.02, *, margin: float = 0.01,
                      dark: float = 0.05, light: float = 0.9, name: str = "board") -> SceneObject:
    """Flat checkerboard of ``rows`` x ``cols`` squares: :func:`board_object` of the equivalent
    ``Board("checkerboard", cols=cols, rows=rows, square=square, margin=margin, dark=dark, light=light)``.

    Board frame: x along columns, y along rows, origin at the first inner corner (see
    :func:`board_corners`), so squares span x in [-square, (cols-1)*square]. Square (row r, col c) is
    dark when r + c is even (the corner square at -x, -y is dark); printed side towards -z. With rows
    and cols both odd (the default 7 x 9) the pattern is symmetric under a 180 degree turn; the default
    :class:`~rangekit.boards.Board` (10 x 7) is not.
    """
    try:
        board = Board("checkerboard", cols=cols, rows=rows, square=square, margin=margin, dark=dark, light=light)
    except InputError as exc:
        raise SceneError(f"calibration_board: {exc}") from exc
    return board_object(board, name=name)


def _builtin_board(*, name: str = "board", **board_fields) -> SceneObject:
    """The builtin "board": :func:`board_object` of ``Board(**board_fields)`` (default: 10 x 7 checkerboard)."""
    try:
        board = Board(**board_fields)
    except (InputError, TypeError) as exc:
        raise SceneError(f"board: {exc}") from exc
    return board_object(board, name=name)


def lumpy(radius: float = 0.06, *, subdivisions: int = 5, seed: int = 0, albedo=0.8,
          specular: float = 0.0, shininess: float = 50.0, name: str = "lumpy") -> SceneObject:
    """Closed, watertight, star-shaped blob with no rotational or mirror symmetry (for registration).

    An icosphere whose radius along unit direction d is ``radius * (1 + sum_k a_k exp(-|d - c_k|^2 /
    (2 s_k^2)))`` with 7 broad Gaussian bumps (5 bumps, 2 dents, |a_k| in [0.12, 0.3], s_k in [0.35, 0.6])
    and 24 small ones (|a_k| in [0.04, 0.1], either sign, s_k in [0.12, 0.22]) at directions c_k drawn
    from ``numpy.random.default_rng(seed)``, then scaled by (1.15, 0.95, 0.8) along x, y, z. The small
    bumps give every region relief, so registration is well conditioned in every direction (a smooth
    egg leaves rotations about its axes nearly free). The factor stays >= 0.4 (star-shaped).
    """
    _check("lumpy", radius=radius)
    _check_count("lumpy", "subdivisions", subdivisions, 0)
    rng = np.random.default_rng(seed)
    c = rng.normal(size=(7, 3))
    c /= np.linalg.norm(c, axis=1, keepdims=True)
    amp = rng.uniform(0.12, 0.3, 7) * rng.permutation([1, 1, 1, 1, 1, -1, -1])
    s = rng.uniform(0.35, 0.6, 7)
    c_small = rng.normal(size=(24, 3))
    c_small /= np.linalg.norm(c_small, axis=1, keepdims=True)
    c = np.r_[c, c_small]
    amp = np.r_[amp, rng.uniform(0.04, 0.1, 24) * rng.choice([-1.0, 1.0], 24)]
    s = np.r_[s, rng.uniform(0.12, 0.22, 24)]
    m = trimesh.creation.icosphere(subdivisions=int(subdivisions), radius=1.0)
    d = np.asarray(m.vertices) / np.linalg.norm(m.vertices, axis=1, keepdims=True)
    d2 = np.sum((d[:, None, :] - c[None]) ** 2, axis=2)  # (V, 31) squared chord distance
    f = 1.0 + np.exp(-d2 / (2 * s**2)) @ amp
    verts = radius * f[:, None] * d * np.array([1.15, 0.95, 0.8])
    return SceneObject(name, verts, np.asarray(m.faces), albedo, specular, shininess)


def turntable_disc(radius: float = 0.15, thickness: float = 0.02, *, albedo=0.3,
                   sections: int = 128) -> SceneObject:
    """Turntable platter: a cylinder, axis z, whose top face is the table top z = 0. Name "turntable"."""
    cyl = cylinder(radius, thickness, sections=sections, albedo=albedo, name="turntable")
    return dataclasses.replace(cyl, vertices=cyl.vertices - [0.0, 0.0, thickness / 2])


def load_mesh(path, *, albedo=0.8, scale: float = 1.0, name: str | None = None) -> SceneObject:
    """Load any mesh file trimesh reads (PLY, OBJ, STL, OFF, GLB, ...) as a :class:`SceneObject`.

    Vertex colours in the file become the albedo (8-bit values / 255, no sRGB decoding); otherwise the
    constant ``albedo`` is used (textures are ignored). Vertices are multiplied by ``scale`` (e.g. 1e-3 for a file in mm).
    Polygons are triangulated by trimesh. ``name`` defaults to the file stem.

    Raises
    ------
    FileFormatError
        If the file is missing, cannot be parsed, has no triangles, or has invalid geometry.
    """
    p = Path(path)
    _check(f"load_mesh({p.name})", scale=scale)
    if not p.is_file():
        raise FileFormatError(f"{p}: no such file; expected a mesh file (.ply, .obj, .stl, .off, .glb)")
    try:
        mesh = trimesh.load(str(p), force="mesh")
    except Exception as exc:  # trimesh raises ValueError, KeyError, IndexError, ... on bad files
        raise FileFormatError(f"{p}: trimesh cannot read it as a mesh ({type(exc).__name__}: {exc})") from exc
    if not isinstance(mesh, trimesh.Trimesh):
        raise FileFormatError(f"{p}: loaded as {type(mesh).__name__}; expected a triangle mesh")
    if len(mesh.faces) == 0:
        raise FileFormatError(f"{p}: the mesh has 0 triangles ({len(mesh.vertices)} vertices); "
                              f"expected a triangle mesh with at least one face")
    if mesh.visual.kind == "vertex":
        albedo = np.asarray(mesh.visual.vertex_colors, dtype=np.float64)[:, :3] / 255.0
    try:
        return SceneObject(name or p.stem, np.asarray(mesh.vertices) * scale, np.asarray(mesh.faces), albedo)
    except SceneError as exc:
        raise FileFormatError(f"{p}: {exc}") from exc


BUILTIN_OBJECTS: dict[str, Callable[..., SceneObject]] = {
    "plane": plane, "sphere": sphere, "box": box, "cylinder": cylinder, "torus": torus,
    "board": _builtin_board, "lumpy": lumpy,
}


def make_object(name_or_path: str, **kwargs) -> SceneObject:
    """A builtin object by name (``BUILTIN_OBJECTS`` key, ``kwargs`` go to its builder) or else a mesh
    file path (``kwargs`` go to :func:`load_mesh`)."""
    if name_or_path in BUILTIN_OBJECTS:
        return BUILTIN_OBJECTS[name_or_path](**kwargs)
    if Path(name_or_path).is_file():
        return load_mesh(name_or_path, **kwargs)
    raise SceneError(f"{name_or_path!r}: neither a builtin object ({', '.join(BUILTIN_OBJECTS)}) "
                     f"nor an existing mesh file")
