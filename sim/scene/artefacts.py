"""The VDI/VDE 2634 part 2 test artefacts, sized and placed for the simulated rig's measuring volume.

**Measuring volume.** A box in the world (turntable) frame: x and y in [-100, 100] mm, z in [40, 140] mm
above the table top (:data:`MEASURING_VOLUME`, 200 x 200 x 100 mm). It is the largest round box centred on
the turntable axis whose corners the default rig's camera and projector both see at least 20 pixels
inside their images (checked by ``tests/app/scan/test_vdi2634.py``). Its diagonal ``L0`` = 300 mm.

**Sizes**, from ``L0`` as the guideline asks (:func:`artefact_sizes`):

- probing sphere: diameter 0.15 L0 = 45 mm (guideline: 0.1-0.2 L0);
- ball bar: spheres of 0.1 L0 = 30 mm, centres 0.4 L0 = 120 mm apart (guideline: length >= 0.3 L0);
- plane: a plate 0.6 L0 x 0.15 L0 = 180 x 45 mm (guideline: length >= 0.5 L0).

**Positions** (:func:`vdi2634_artefacts`), the guideline's counts: the sphere in 10 positions (the 8
corners of the volume inset by the radius plus 2 mm, its centre, the centre of its bottom half), the
ball bar in 7 (centred in the volume along the 4 body diagonals, the x and y axes and the x-y diagonal),
the plate in 6 (facing the rig, long side horizontal, turned by 0 and +-15 degrees about its normal;
lying flat along y and along x; facing the rig, raised to the back top of the volume). Every artefact
lies inside the volume. The artefacts float (no stand, no turntable in the scene); a ball bar's bar is
not modelled (it is thin and lies outside the spheres' evaluation caps).

**Spheres are icospheres** of 6 subdivisions with every vertex exactly on the sphere: the facets lie
inside it by at most 7.1e-5 R (1.6 um on the 45 mm sphere, 1.1 um on the 30 mm balls), which bounds what
the tessellation adds to PF and PS (``tests/app/scan/test_vdi2634.py`` measures it).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from rangekit.geometry import axis_angle_to_R, make_T
from rangekit.rig.rig_file import Rig
from rangekit.sim.scene.objects import plane, sphere
from rangekit.sim.scene.scene import Scene
from rangekit.sim.scene.scene_object import SceneObject

__all__ = ["MEASURING_VOLUME", "L0", "ArtefactSizes", "Artefact", "artefact_sizes", "vdi2634_artefacts",
           "SPHERE_SUBDIVISIONS", "GUIDELINE_POSITIONS"]

#: (lo, hi) corners of the measuring volume, world (turntable) frame, metres.
MEASURING_VOLUME = (np.array([-0.10, -0.10, 0.04]), np.array([0.10, 0.10, 0.14]))
#: The measuring volume's diagonal (metres).
L0 = float(np.linalg.norm(MEASURING_VOLUME[1] - MEASURING_VOLUME[0]))
SPHERE_SUBDIVISIONS = 6
#: Positions of the sphere, the ball bar and the plane the guideline asks for.
GUIDELINE_POSITIONS = (10, 7, 6)
_INSET = 0.002   # metres between an artefact and the volume's faces


@dataclass(frozen=True)
class ArtefactSizes:
    """Calibrated dimensions (metres) of the artefacts for a measuring volume of diagonal ``L0``."""

    L0: float
    sphere_diameter: float
    ball_diameter: float
    bar_length: float
    plate_length: float
    plate_width: float


def artefact_sizes(l0: float = L0) -> ArtefactSizes:
    """The guideline's sizes for a volume of diagonal ``l0`` (module doc)."""
    return ArtefactSizes(L0=l0, sphere_diameter=0.15 * l0, ball_diameter=0.1 * l0, bar_length=0.4 * l0,
                         plate_length=0.6 * l0, plate_width=0.15 * l0)


@dataclass(frozen=True, eq=False)
class Artefact:
    """One artefact at one position.

    kind : "sphere", "ballbar" or "plane". label : e.g. "ball bar 3 (body diagonal -x+y+z)".
    objects : its scene objects, named "sphere"; "ball_a", "ball_b"; "plate" (world frame).
    centres : (k, 3) true sphere centres (k = 1 sphere, 2 ball bar, 0 plane), metres.
    diameter : calibrated sphere diameter (0 for a plane). length : calibrated ball bar length (0 otherwise).
    corners : (4, 3) the plate's true corners (empty otherwise).
    """

    kind: str
    label: str
    objects: tuple[SceneObject, ...]
    centres: np.ndarray
    diameter: float = 0.0
    length: float = 0.0
    corners: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))

    def scene(self) -> Scene:
        """The artefact alone in the rig's world."""
        return Scene(self.objects)


@lru_cache(maxsize=8)
def _sphere_at_origin(name: str, d: float) -> SceneObject:
    s = sphere(d / 2, subdivisions=SPHERE_SUBDIVISIONS, name=name)
    return SceneObject(s.name, s.vertices, s.triangles, s.vertex_albedo, on_turntable=False)


def _sphere(name: str, d: float, c: np.ndarray) -> SceneObject:
    return _sphere_at_origin(name, float(d)).with_pose(make_T(t=c))


def _sphere_positions(r: float) -> list[tuple[str, np.ndarray]]:
    lo, hi = MEASURING_VOLUME[0] + r + _INSET, MEASURING_VOLUME[1] - r - _INSET
    centre = (MEASURING_VOLUME[0] + MEASURING_VOLUME[1]) / 2
    out = []
    for i, (sx, sy, sz) in enumerate(np.array(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij")).reshape(3, -1).T):
        c = np.where([sx, sy, sz], hi, lo)
        out.append((f"corner {'+' if sx else '-'}x{'+' if sy else '-'}y{'+' if sz else '-'}z", c))
    out.append(("centre", centre))
    out.append(("bottom centre", np.array([centre[0], centre[1], (lo[2] + centre[2]) / 2])))
    return out


_BAR_DIRECTIONS = [("body diagonal +x+y+z", (1, 1, 0.5)), ("body diagonal +x-y+z", (1, -1, 0.5)),
                   ("body diagonal -x+y+z", (-1, 1, 0.5)), ("body diagonal -x-y+z", (-1, -1, 0.5)),
                   ("x axis", (1, 0, 0)), ("y axis", (0, 1, 0)), ("x-y diagonal", (1, 1, 0))]


def _facing(rig: Rig) -> np.ndarray:
    """Unit bisector of the directions from the volume's centre to the camera and to the projector."""
    centre = (MEASURING_VOLUME[0] + MEASURING_VOLUME[1]) / 2
    u = [(c.center - centre) / np.linalg.norm(c.center - centre) for c in (rig.camera, rig.projector)]
    n = u[0] + u[1]
    return n / np.linalg.norm(n)


def _plate(n: np.ndarray, long_axis: np.ndarray, c: np.ndarray, sizes: ArtefactSizes) -> tuple[SceneObject, np.ndarray]:
    a = long_axis - (long_axis @ n) * n
    a /= np.linalg.norm(a)
    R = np.stack([a, np.cross(n, a), n], axis=1)          # plate x = long side, z = normal
    p = plane(sizes.plate_length, sizes.plate_width, name="plate")
    obj = SceneObject(p.name, p.vertices, p.triangles, p.vertex_albedo, T_world_obj=make_T(R, c), on_turntable=False,
                      smooth=False)
    hx, hy = sizes.plate_length / 2, sizes.plate_width / 2
    corners = c + np.array([[sx * hx, sy * hy, 0.0] for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]) @ R.T
    return obj, corners


def _plate_positions(rig: Rig) -> list[tuple[str, np.ndarray, np.ndarray, np.ndarray]]:
    """(label, normal, long axis, centre) of the six plate positions."""
    n = _facing(rig)
    centre = (MEASURING_VOLUME[0] + MEASURING_VOLUME[1]) / 2
    x = np.array([1.0, 0.0, 0.0])
    out = [(f"facing the rig, turned {deg:+d} deg", n, axis_angle_to_R(n, np.radians(deg)) @ x, centre)
           for deg in (0, 15, -15)]
    out.append(("lying flat along y", np.array([0.0, 0.0, 1.0]), np.array([0.0, 1.0, 0.0]),
                centre + [0.0, 0.0, -0.02]))
    out.append(("lying flat along x, low", np.array([0.0, 0.0, 1.0]), x, centre + [0.0, 0.03, -0.04]))
    out.append(("facing the rig, back top", n, x, centre + [0.0, 0.05, 0.02]))
    return out


def vdi2634_artefacts(rig: Rig, *, n_spheres: int = GUIDELINE_POSITIONS[0], n_bars: int = GUIDELINE_POSITIONS[1],
                      n_planes: int = GUIDELINE_POSITIONS[2],
                      sizes: ArtefactSizes | None = None) -> list[Artefact]:
    """The artefacts at their positions (module doc), the first ``n_*`` of each kind, spheres first.

    ``rig`` sets which way the plates face (the bisector of the camera's and projector's directions).
    """
    sz = sizes or artefact_sizes()
    out = []
    for i, (label, c) in enumerate(_sphere_positions(sz.sphere_diameter / 2)[:n_spheres]):
        out.append(Artefact("sphere", f"sphere {i + 1} ({label})", (_sphere("sphere", sz.sphere_diameter, c),),
                            c[None, :], diameter=sz.sphere_diameter))
    centre = (MEASURING_VOLUME[0] + MEASURING_VOLUME[1]) / 2
    for i, (label, d) in enumerate(_BAR_DIRECTIONS[:n_bars]):
        d = np.asarray(d, dtype=np.float64) / np.linalg.norm(d)
        a, b = centre - d * sz.bar_length / 2, centre + d * sz.bar_length / 2
        out.append(Artefact("ballbar", f"ball bar {i + 1} ({label})",
                            (_sphere("ball_a", sz.ball_diameter, a), _sphere("ball_b", sz.ball_diameter, b)),
                            np.stack([a, b]), diameter=sz.ball_diameter, length=sz.bar_length))
    for i, (label, n, axis, c) in enumerate(_plate_positions(rig)[:n_planes]):
        obj, corners = _plate(n, axis, c, sz)
        out.append(Artefact("plane", f"plane {i + 1} ({label})", (obj,), np.zeros((0, 3)), corners=corners))
    return out
