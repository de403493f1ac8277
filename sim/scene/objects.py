"""Procedurally built triangle-mesh objects for the simulated scanning rig.

Every builder returns a :class:`SceneObject` in its own natural frame (metres, pose identity) with
outward-facing (counter-clockwise seen from outside) triangles and a per-vertex linear RGB albedo.
Place it with :meth:`SceneObject.placed_on_table` or :meth:`SceneObject.with_pose`.
"""

from __future__ import annotations

import dataclasses
from functools import lru_cache
from pathlib import Path
from typing import Callable

import numpy as np
import trimesh

from rangekit.boards import Board
from rangekit._runtime.memory import forgettable_cache
from rangekit.errors import FileFormatError, InputError, SceneError
from rangekit.sim.scene.scene_object import PlanarTexture, SceneObject
from rangekit.sim.scene.zoo import bowl, bunny, steps, thin

__all__ = ["plane", "sphere", "box", "cylinder", "torus", "board_object",
           "calibration_board", "board_corners", "lumpy", "shiny", "dark", "turntable_disc", "load_scene_object",
           "BUILTIN_OBJECTS", "OBJECT_NOTES", "make_object"]


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


def board_object(board: Board, *, name: str = "board", texel: float | None = None) -> SceneObject:
    """A flat calibration board: one quad over the board's texture extent, textured with ``board.texture``.

    Board frame as in :mod:`rangekit.boards`: z = 0 plane, corners at ``board.object_points()``, printed
    side facing -z (the triangles face -z, so the texture is seen from -z and the back is plain). Flat
    shaded; the vertex albedo is the texture's mean (what ``to_trimesh`` and views from behind show).
    ``texel`` (metres) must divide ``board.square``; default 0.1 mm, or the texel nearest it that divides the
    square (a 20.05 mm square: 0.10025 mm), so that any square a user gives (``--square-mm``) can be drawn.
    """
    if not isinstance(board, Board):
        raise SceneError(f"board_object: board must be a rangekit.boards.Board, found {type(board).__name__}")
    if texel is None:
        texel, n = 1e-4, board.square / 1e-4
        if abs(n - round(n)) > 1e-6 * max(n, 1.0):
            texel = board.square / max(1, round(n))
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


forgettable_cache(_board_texture.cache_clear)


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


def shiny(*, specular: float = 1.5, shininess: float = 60.0, albedo=0.5, name: str = "shiny", **lumpy_options) -> SceneObject:
    """The zoo's shiny object: :func:`lumpy`'s shape with a strong Blinn-Phong lobe (``specular`` k_s, the
    peak of the lobe, is 3x the diffuse albedo), so the default camera saturates in its highlights."""
    return lumpy(specular=specular, shininess=shininess, albedo=albedo, name=name, **lumpy_options)


def dark(*, albedo=0.05, name: str = "dark", **lumpy_options) -> SceneObject:
    """The zoo's dark object: :func:`lumpy`'s shape with albedo 0.05 (the blob's is 0.8): 16x less signal."""
    return lumpy(albedo=albedo, name=name, **lumpy_options)


def turntable_disc(radius: float = 0.15, thickness: float = 0.02, *, albedo=0.3,
                   sections: int = 128) -> SceneObject:
    """Turntable platter: a cylinder, axis z, whose top face is the table top z = 0. Name "turntable"."""
    cyl = cylinder(radius, thickness, sections=sections, albedo=albedo, name="turntable")
    return dataclasses.replace(cyl, vertices=cyl.vertices - [0.0, 0.0, thickness / 2])


def load_scene_object(path, *, albedo=0.8, scale: float = 1.0, name: str | None = None) -> SceneObject:
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
    _check(f"load_scene_object({p.name})", scale=scale)
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
    "bunny": bunny, "thin": thin, "bowl": bowl, "shiny": shiny, "dark": dark, "steps": steps,
}

#: One line per built-in object: what it is for, or what makes it hard to scan (``rangekit sim objects``).
OBJECT_NOTES: dict[str, str] = {
    "plane": "flat 400 x 300 mm rectangle: flatness, plane fits",
    "sphere": "50 mm radius ball: symmetric, so registration alone cannot fix the turntable angle",
    "box": "flat faces and sharp edges; the symmetric views are ambiguous",
    "cylinder": "rotationally symmetric: registration needs the turntable prior",
    "torus": "hole through the middle, self-occlusion",
    "board": "calibration board (10 x 7 checkerboard), flat and textured",
    "lumpy": "the default blob: smooth, bumpy everywhere, well conditioned for registration (the easy case)",
    "bunny": "Stanford bunny upright: ears (thin, occluding), concave neck, open underneath",
    "thin": "1 and 2 mm fins, 2 mm pins, a 2 x 22 mm slot: mixed pixels, parts thinner than the fusion voxel",
    "bowl": "concave: the inside sees its own walls (interreflection), deep occlusion, rotationally symmetric",
    "shiny": "lumpy with a strong specular lobe: highlights saturate the camera",
    "dark": "lumpy at albedo 0.05: 16x less signal than the blob, noise-limited decoding",
    "steps": "step gauge 5/10/15/20 mm: sharp edges and depth jumps (mixed pixels), known heights",
}


def make_object(name_or_path: str, **kwargs) -> SceneObject:
    """A builtin object by name (``BUILTIN_OBJECTS`` key, ``kwargs`` go to its builder) or else a mesh
    file path (``kwargs`` go to :func:`load_scene_object`)."""
    if name_or_path in BUILTIN_OBJECTS:
        return BUILTIN_OBJECTS[name_or_path](**kwargs)
    if Path(name_or_path).is_file():
        return load_scene_object(name_or_path, **kwargs)
    raise SceneError(f"{name_or_path!r}: neither a builtin object ({', '.join(BUILTIN_OBJECTS)}) "
                     f"nor an existing mesh file")
