"""A laser sheet seen by two cameras (Fusiello 2024, 13.2.1 item 3): the laser rig with a second camera beside
the first, each rendering the same turntable position's laser frames, with exact truth.

Geometry (world = turntable frame, metres): the left camera is :func:`rangekit.sim.laser.rig.laser_rig`'s camera
(the default rig's, so its frames are byte for byte those of the single-camera laser capture of the same seed and
angle), the lasers are its two Ciclop-like lasers at +-30 degrees about the turntable axis. The right camera is
the left one turned by :data:`RIGHT_AZIMUTH_DEG` about the turntable axis (towards laser 0, the world's +x, the
left camera's +x: a horizontal pair converging on the axis), its baseline 2 x 0.453 m x sin(azimuth / 2) (181 mm
at 23 degrees), with intrinsics and a lens of its own (a second camera, not a copy). 23 degrees keeps it clear of
laser 0's emitter (30 degrees) while the rays converge almost as much as camera and laser do (accuracy,
:mod:`rangekit.laser.sheet_stereo`); the second camera sees laser 0's line nearly head on and laser 1's from 53
degrees, where more of it is hidden from it (docs/laser.md, "Two cameras, no plane calibration").

Noise: the left view has the capture's seed, the right one ``seed + RIGHT_SEED_OFFSET`` (its own sensor noise and
speckle). Truth per camera: the lit curves it sees (dense samples, world points and distorted pixels), and which
of the left curve's samples the right camera sees too (:func:`seen_by`), the points stereo can reconstruct.
"""

from __future__ import annotations

import math
from dataclasses import asdict, replace
from pathlib import Path
from typing import Callable

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.errors import SceneError
from rangekit.formats.laser_capture import LASER_STEREO_KIND
from rangekit.geometry import axis_angle_to_R, make_T
from rangekit.io import atomic_save_npz, atomic_write_json, write_png
from rangekit.rig.rig_file import Rig, save_rig
from rangekit.sim.imaging.render import ImagingModel
from rangekit.sim.laser.curve import cast_first_hits
from rangekit.sim.laser.frames import LaserLook, LaserView
from rangekit.sim.laser.rig import laser_rig
from rangekit.sim.scene.scene import Scene
from rangekit.formats.sessions.files import RIG_FILE

__all__ = ["RIGHT_AZIMUTH_DEG", "RIGHT_SEED_OFFSET", "laser_stereo_rig", "LaserStereoView", "seen_by",
           "write_laser_stereo_capture"]

#: The right camera's place: the left camera turned by this many degrees about the turntable axis.
RIGHT_AZIMUTH_DEG = 23.0
#: The right view's noise seed is the capture's seed plus this.
RIGHT_SEED_OFFSET = 7919


def laser_stereo_rig(rig: Rig | None = None, *, azimuth_deg: float = RIGHT_AZIMUTH_DEG, **laser_options) -> Rig:
    """:func:`laser_rig` (``rig`` and ``laser_options`` go to it) with a second camera: the first turned by
    ``azimuth_deg`` about the turntable axis, its own intrinsics and lens (module doc). ``cameras = (left,
    right)``; no projector."""
    base = laser_rig(rig, **laser_options)
    if base.T_world_table is None:
        raise SceneError("laser_stereo_rig: the rig has no turntable (T_world_table); the second camera is placed "
                         "by turning the first about its axis")
    if not (np.isfinite(azimuth_deg) and 5.0 <= abs(azimuth_deg) <= 90.0):
        raise SceneError(f"laser_stereo_rig: azimuth_deg must be 5 to 90 degrees either way, found {azimuth_deg!r}")
    left = base.camera
    T = base.T_world_table
    R = axis_angle_to_R(T[:3, 2], math.radians(azimuth_deg))
    turn = make_T(R, T[:3, 3] - R @ T[:3, 3])          # about the axis through the table centre
    s = left.width / 1280.0
    K = np.array([[1792.0 * s, 0.0, left.K[0, 2] - 6.1 * s], [0.0, 1793.1 * s, left.K[1, 2] + 4.3 * s],
                  [0.0, 0.0, 1.0]])
    right = PinholeCamera(K, left.width, left.height, np.array([-0.065, 0.095, -1.5e-4, 2.5e-4, 0.0]),
                          turn @ left.T_world_cam, name="right")
    left = PinholeCamera(left.K, left.width, left.height, left.dist, left.T_world_cam, name="left")
    devices = {k: v for k, v in base.devices.items() if k != "projector"}
    return replace(base, cameras=(left, right), projector=None, devices=devices, projector_response=None)


def seen_by(view: LaserView, camera: PinholeCamera, laser, xyz: np.ndarray, face: np.ndarray, *,
            eps: float = 2e-5) -> np.ndarray:
    """(N,) bool: which samples of ``laser``'s lit curve in ``view`` (world ``xyz`` (N, 3) on triangles ``face``
    (N,) of its posed mesh) ``camera`` sees: on the side of their triangle the laser lights, nothing in between
    (a ray cast from its centre), inside its image. The rules of :func:`rangekit.sim.laser.curve.lit_curve`."""
    if len(xyz) == 0:
        return np.zeros(0, dtype=bool)
    mesh = view.mesh
    tri = mesh.triangles[face]
    v0 = mesh.vertices[tri[:, 0]]
    n = np.cross(mesh.vertices[tri[:, 1]] - v0, mesh.vertices[tri[:, 2]] - v0)
    ok = np.einsum("ij,ij->i", n, laser.origin - v0) * np.einsum("ij,ij->i", n, camera.center - v0) > 0
    v = xyz - camera.center
    dist = np.linalg.norm(v, axis=1)
    t, prim = cast_first_hits(view.rc_scene, np.broadcast_to(camera.center, xyz.shape), v / dist[:, None])
    ok &= (prim == face) | (t >= dist - eps)
    uv = camera.project(xyz)
    W, H = camera.width, camera.height
    with np.errstate(invalid="ignore"):
        ok &= (uv[:, 0] >= -0.5) & (uv[:, 0] < W - 0.5) & (uv[:, 1] >= -0.5) & (uv[:, 1] < H - 0.5)
    return ok


class LaserStereoView:
    """The laser frames of ``scene`` on a two-camera laser ``rig`` (:func:`laser_stereo_rig`) at turntable
    ``angle`` radians: ``left`` and ``right``, one :class:`~rangekit.sim.laser.frames.LaserView` per camera (each
    a rig whose only camera is that one). Keywords as LaserView's; the right view's seed is ``seed +
    RIGHT_SEED_OFFSET``."""

    def __init__(self, scene: Scene, rig: Rig, angle: float = 0.0, *, imaging: ImagingModel | None = None,
                 look: LaserLook | None = None, seed: int = 0, ambient_scale: int = 1) -> None:
        if len(rig.cameras) < 2:
            raise SceneError(f"laser stereo rendering: the rig needs two cameras, found {len(rig.cameras)}; use "
                             "rangekit.sim.laser.stereo.laser_stereo_rig()")
        self.rig, self.angle, self.seed = rig, float(angle), int(seed)
        self.left, self.right = (
            LaserView(scene, replace(rig, cameras=(cam,)), angle, imaging=imaging, look=look, seed=s,
                      ambient_scale=ambient_scale)
            for cam, s in ((rig.cameras[0], self.seed), (rig.cameras[1], self.seed + RIGHT_SEED_OFFSET)))
        self._both: dict[int, np.ndarray] = {}

    def both(self, k: int) -> np.ndarray:
        """(N,) bool over laser ``k``'s left curve samples (``left.curve(k)``): the right camera sees them too."""
        if k not in self._both:
            c = self.left.curve(k)
            self._both[k] = seen_by(self.left, self.rig.cameras[1], self.rig.lasers[k], c.xyz, c.face)
        return self._both[k]


def write_laser_stereo_capture(view: LaserStereoView, out_dir: str | Path, *, info: dict | None = None,
                               progress: Callable[[str], None] | None = None) -> list[Path]:
    """Render the off frame and one frame per laser in both cameras of ``view``; write the capture folder
    (:mod:`rangekit.formats.laser_capture`, the two-camera kind). Returns the image paths.

    Layout (every file atomically)::

        left/off.png, left/laser0.png, ...    the left camera's frames (as a one-camera laser capture's)
        right/off.png, right/laser0.png, ...  the right camera's
        rig.json        cameras (left, right), T_world_table, lasers (their planes are not used to reconstruct)
        capture.json    kind "rangekit.laser_stereo/1", n_lasers, channels, turntable_angle_rad, seed, right_seed,
                        objects, imaging, look
        ground_truth.npz  per camera S (left, right) and laser k: S_laser{k}_curve_uv (N, 2) distorted pixels and
                        S_laser{k}_curve_xyz (N, 3) world points of the lit curve's dense samples that camera sees
                        (<= 0.5 px apart); left_laser{k}_both (N,) bool: the right camera sees that left sample
                        too; S_T_world_cam (4, 4); with ambient_scale 1, S_depth (H, W) camera z (NaN: no surface)
                        and S_hit (H, W) bool. World: the rig's, the object posed at the angle.
    """
    out = Path(out_dir)
    say = progress or (lambda msg: None)
    n = len(view.rig.lasers)
    say(f"rendering the laser-off frame and {n} laser frame(s) in two cameras at {np.degrees(view.angle):g} deg")
    truth, paths = {}, []
    for side, v in (("left", view.left), ("right", view.right)):
        (out / side).mkdir(parents=True, exist_ok=True)
        paths.append(out / side / "off.png")
        write_png(paths[-1], v.off())
        truth[f"{side}_T_world_cam"] = v.camera.T_world_cam
        if v.depth is not None:
            truth[f"{side}_depth"], truth[f"{side}_hit"] = v.depth, v.geometry.hit
        for k in range(n):
            frame = v.frame(k)
            if len(frame.curve.uv) == 0:
                say(f"warning: laser {k} ({view.rig.lasers[k].name}) lights nothing the {side} camera sees")
            paths.append(out / side / f"laser{k}.png")
            write_png(paths[-1], frame.image)
            truth[f"{side}_laser{k}_curve_uv"] = frame.curve.uv
            truth[f"{side}_laser{k}_curve_xyz"] = frame.curve.xyz
    for k in range(n):
        truth[f"left_laser{k}_both"] = view.both(k)
    save_rig(view.rig, out / RIG_FILE)
    atomic_write_json(out / "capture.json", {
        "kind": LASER_STEREO_KIND, "n_lasers": n, "channels": [laser.channel for laser in view.rig.lasers],
        "turntable_angle_rad": view.angle, "seed": view.seed, "right_seed": view.seed + RIGHT_SEED_OFFSET,
        "objects": list(view.left.mesh.object_names), "imaging": asdict(view.left.imaging),
        "look": asdict(view.left.look), **(info or {})})
    atomic_save_npz(out / "ground_truth.npz", **truth)
    say(f"wrote {len(paths)} image(s), ground_truth.npz and {RIG_FILE} to {out}")
    return paths
