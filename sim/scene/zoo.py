"""The zoo of hard objects (issue 18): thin parts, a concavity, sharp steps, and the Stanford bunny.

Every builder returns a :class:`SceneObject` in its own frame (metres, pose identity, z up, lowest point
at z = 0 so it stands on the plate as built), watertight with outward-facing triangles (the bunny is the
scanned mesh as it is: open underneath). The mesh is the truth the simulator's evaluation measures
against (:mod:`rangekit.sim.truth.evaluate`). The shiny and dark members are materials on the ``lumpy`` blob
(:mod:`rangekit.sim.scene.objects`, which registers all of them in ``BUILTIN_OBJECTS``).

Sizes in the docstrings are the analytic truth the tests check (tests/sim/test_zoo.py).
"""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path

import numpy as np

from rangekit.errors import MissingDataError, SceneError
from rangekit.geometry import R_up_to_z
from rangekit.sim.scene.scene_object import SceneObject

__all__ = ["thin", "bowl", "steps", "bunny", "bunny_path", "data_folders", "THIN_FINS", "THIN_PIN_DIAMETER",
           "THIN_SLOT", "STEP_HEIGHTS", "BUNNY_FILE"]

#: Fin thicknesses of :func:`thin`, metres (fins 40 mm tall on an 8 mm base).
THIN_FINS = (0.001, 0.002)
#: Pin diameter of :func:`thin`, metres (pins 30 mm tall).
THIN_PIN_DIAMETER = 0.002
#: The slot of :func:`thin`: width and depth, metres (between two 30 mm blocks, down to the 8 mm base).
THIN_SLOT = (0.002, 0.022)
#: Step heights of :func:`steps` above the plate, metres.
STEP_HEIGHTS = (0.005, 0.010, 0.015, 0.020)
#: The Stanford bunny's merged mesh, relative to a data folder (:func:`data_folders`).
BUNNY_FILE = "stanford-bunny/bun_zipper.ply"

_ROOT = Path(__file__).resolve().parents[2]   # the checkout (sim/scene/zoo.py; sim/ is the top folder of rangekit.sim)


# --- meshes from profiles -----------------------------------------------------------------------------

def _column_prism(xs, heights, depth: float) -> tuple[np.ndarray, np.ndarray]:
    """A prism over a histogram profile: columns ``[xs[i], xs[i+1]] x [0, heights[i]]`` in the x-z plane,
    extruded over y in ``[-depth / 2, depth / 2]``. Returns (V, 3) vertices and (F, 3) outward triangles,
    watertight (no T-junctions: each cap column is a ladder between the levels on its two sides)."""
    xs, h = np.asarray(xs, dtype=np.float64), np.asarray(heights, dtype=np.float64)
    n = len(h)
    levels = [sorted({0.0, *(h[k] for k in (i - 1, i) if 0 <= k < n)}) for i in range(n + 1)]
    index = {}
    for i, lv in enumerate(levels):
        for z in lv:
            index[i, z] = len(index)
    pts = np.array([(xs[i], z) for (i, z) in index])
    cap = []                                        # counter-clockwise in (x, z): normal -y
    for i in range(n):
        L = [(i, z) for z in levels[i] if z <= h[i]]
        R = [(i + 1, z) for z in levels[i + 1] if z <= h[i]]
        a = b = 0
        while a < len(L) - 1 or b < len(R) - 1:
            if b == len(R) - 1 or (a < len(L) - 1 and L[a + 1][1] <= R[b + 1][1]):
                cap.append((index[L[a]], index[R[b]], index[L[a + 1]]))
                a += 1
            else:
                cap.append((index[L[a]], index[R[b]], index[R[b + 1]]))
                b += 1
    ring = [(i, 0.0) for i in range(n + 1)] + [(n, h[-1])]
    for i in range(n - 1, 0, -1):
        ring += [(i, h[i])] + ([(i, h[i - 1])] if h[i - 1] != h[i] else [])
    ring = [index[k] for k in ring + [(0, h[0])]]   # counter-clockwise boundary of the profile
    m = len(pts)
    verts = np.vstack([np.c_[pts[:, 0], np.full(m, -depth / 2), pts[:, 1]],
                       np.c_[pts[:, 0], np.full(m, depth / 2), pts[:, 1]]])
    cap = np.array(cap)
    a, b = np.array(ring), np.roll(ring, -1)
    sides = np.concatenate([np.c_[a, b + m, b], np.c_[a, a + m, b + m]])
    return verts, np.concatenate([cap, cap[:, ::-1] + m, sides]).astype(np.int64)


def _lathe(profile_rz, sections: int) -> tuple[np.ndarray, np.ndarray]:
    """A solid of revolution about z: ``profile_rz`` (P, 2) runs from a point on the axis (r = 0) through
    points with r > 0 to another point on the axis, with the solid on its left (counter-clockwise in the
    r-z half plane). Returns (V, 3) vertices (every one on the true surface) and outward triangles."""
    prof = np.asarray(profile_rz, dtype=np.float64)
    inner = prof[1:-1]
    k = len(inner)
    t = 2 * np.pi * np.arange(sections) / sections
    rings = np.stack([inner[:, :1] * np.cos(t), inner[:, :1] * np.sin(t),
                      np.broadcast_to(inner[:, 1:], (k, sections))], -1).reshape(-1, 3)   # vertex p * S + s
    verts = np.vstack([rings, [[0.0, 0.0, prof[0, 1]], [0.0, 0.0, prof[-1, 1]]]])
    first, last = k * sections, k * sections + 1
    s, s1 = np.arange(sections), (np.arange(sections) + 1) % sections
    p = np.arange(k - 1)[:, None]
    a, b, c, d = p * sections + s, p * sections + s1, (p + 1) * sections + s1, (p + 1) * sections + s
    quads = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    fans = np.concatenate([np.c_[np.full(sections, first), s1, s],
                           np.c_[np.full(sections, last), (k - 1) * sections + s, (k - 1) * sections + s1]])
    return verts, np.concatenate([quads, fans]).astype(np.int64)


def _pin(x: float, y: float, diameter: float, height: float, sections: int):
    v, f = _lathe([(0.0, 0.0), (diameter / 2, 0.0), (diameter / 2, height), (0.0, height)], sections)
    return v + [x, y, 0.0], f


def _join(parts) -> tuple[np.ndarray, np.ndarray]:
    """Disjoint closed pieces as one vertex and triangle array."""
    offsets = np.cumsum([0] + [len(v) for v, _ in parts])
    return (np.vstack([v for v, _ in parts]),
            np.vstack([f + o for (_, f), o in zip(parts, offsets)]))


# --- the zoo ------------------------------------------------------------------------------------------

def thin(*, albedo=0.8, pin_sections: int = 48, name: str = "thin") -> SceneObject:
    """Thin features: a comb 60 mm long (x) and 30 mm deep (y) on an 8 mm base, with a 1 mm and a 2 mm fin
    40 mm tall (:data:`THIN_FINS`, at x in [10, 11] and [20, 22] mm), two 30 mm blocks with a 2 mm slot
    between them (x in [46, 48] mm, 22 mm deep: :data:`THIN_SLOT`); and in front of it (y = -22 mm),
    standing on the plate, three pins of 2 mm diameter (:data:`THIN_PIN_DIAMETER`) 30 mm tall at x = 10,
    30, 50 mm. Object frame: the comb from x = 0, centred on y = 0; all on z = 0. Flat shaded (sharp
    edges); the pins are ``pin_sections``-gons with their corners on the 1 mm circle.
    """
    mm = 1e-3
    xs = np.array([0, 10, 11, 20, 22, 40, 46, 48, 54, 60]) * mm
    hs = np.array([8, 40, 8, 40, 8, 30, 8, 30, 8]) * mm
    comb = _column_prism(xs, hs, 30 * mm)
    pins = [_pin(x * mm, -22 * mm, THIN_PIN_DIAMETER, 30 * mm, int(pin_sections)) for x in (10, 30, 50)]
    return SceneObject(name, *_join([comb, *pins]), albedo, smooth=False)


def bowl(*, outer_radius: float = 0.06, inner_radius: float = 0.05, foot: float = 0.004, sections: int = 128,
         arc_points: int = 48, albedo=0.8, name: str = "bowl") -> SceneObject:
    """A hemispherical bowl, open at the top: the wall lies between two spheres about the centre
    ``(0, 0, outer_radius - foot)`` of radii ``outer_radius`` and ``inner_radius`` (10 mm thick by default),
    cut at the centre's height by the flat rim and at z = 0 by the flat foot (the outer sphere loses its
    bottom ``foot`` metres). Default: 120 mm across, 56 mm tall, the inside floor at z = 6 mm. Every vertex
    of the outer (inner) surface lies exactly on its sphere; smooth shaded.
    """
    if not 0 < inner_radius < outer_radius - foot or not 0 < foot < outer_radius:
        raise SceneError(f"bowl: need 0 < foot < outer_radius and 0 < inner_radius < outer_radius - foot, found "
                         f"outer_radius={outer_radius!r}, inner_radius={inner_radius!r}, foot={foot!r}")
    zc = outer_radius - foot
    lo = np.arccos(zc / outer_radius)                      # polar angle (from -z) of the foot's edge
    up = np.linspace(lo, np.pi / 2, arc_points)
    down = np.linspace(np.pi / 2, 0.0, arc_points)[:-1]
    profile = np.vstack([[0.0, 0.0],
                         np.c_[outer_radius * np.sin(up), zc - outer_radius * np.cos(up)],
                         np.c_[inner_radius * np.sin(down), zc - inner_radius * np.cos(down)],
                         [0.0, zc - inner_radius]])
    return SceneObject(name, *_lathe(profile, int(sections)), albedo)


def steps(*, heights=STEP_HEIGHTS, width: float = 0.015, depth: float = 0.04, albedo=0.8,
          name: str = "steps") -> SceneObject:
    """A step gauge: a staircase of flat-topped steps ``width`` metres long (x) each, ``depth`` deep (y),
    at ``heights`` above the plate (default :data:`STEP_HEIGHTS`: 5, 10, 15, 20 mm), sharp 90 degree
    edges. Object frame: x from 0, centred on y = 0. Flat shaded."""
    h = np.asarray(heights, dtype=np.float64)
    if h.ndim != 1 or len(h) < 1 or not np.all(np.isfinite(h) & (h > 0)) or not (width > 0 and depth > 0):
        raise SceneError(f"steps: need heights > 0 and width, depth > 0 (metres), found heights={heights!r}, "
                         f"width={width!r}, depth={depth!r}")
    return SceneObject(name, *_column_prism(width * np.arange(len(h) + 1), h, depth), albedo, smooth=False)


def data_folders() -> list[Path]:
    """Where the shared real data is looked for: ``$RANGEKIT_DATA`` alone when set (an empty folder hides the
    data: ``make test-bare``), else ``../shared/data`` beside the checkout and beside the folder holding it (a git
    worktree)."""
    env = os.environ.get("RANGEKIT_DATA")
    return [Path(env)] if env else [_ROOT.parent / "shared" / "data", _ROOT.parent.parent / "shared" / "data"]


def bunny_path() -> Path:
    """The first of :func:`data_folders` holding :data:`BUNNY_FILE`, else the path in the first folder."""
    paths = [folder / BUNNY_FILE for folder in data_folders()]
    return next((p for p in paths if p.is_file()), paths[0])


def bunny(path: str | os.PathLike | None = None, *, albedo=0.8, name: str = "bunny") -> SceneObject:
    """The Stanford bunny (``bun_zipper.ply``, metres, 35,947 vertices, 69,451 triangles) turned upright:
    the file is y-up, so +y becomes +z (:func:`rangekit.geometry.R_up_to_z`), and its lowest point is
    moved to z = 0. The mesh is open underneath (the scanner never saw the base). ``path`` defaults to
    :func:`bunny_path`.

    Raises
    ------
    MissingDataError
        If the file is missing, naming the path and where the data is looked for.
    """
    p = Path(path) if path is not None else bunny_path()
    if not p.is_file():
        where = ", ".join(str(f) for f in data_folders())
        raise MissingDataError(f"bunny: {p} not found; expected the Stanford bunny mesh {BUNNY_FILE} in a data folder "
                         f"(looked in {where}; set RANGEKIT_DATA to the folder holding stanford-bunny/)")
    verts, tris = _upright(str(p.resolve()))
    return SceneObject(name, verts, tris, albedo)


@lru_cache(maxsize=2)
def _upright(path: str) -> tuple[np.ndarray, np.ndarray]:
    """(V, 3) upright vertices (lowest at z = 0) and (F, 3) triangles of a y-up mesh file, read once."""
    from rangekit.formats.meshes import load_mesh

    mesh = load_mesh(path)
    v = mesh.vertices @ R_up_to_z([0.0, 1.0, 0.0]).T
    v[:, 2] -= v[:, 2].min()
    v.flags.writeable = False
    return v, np.asarray(mesh.triangles)
