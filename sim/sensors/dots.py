"""A simulated single-camera random-dot sensor (Kinect v1, PrimeSense; Fusiello 13.2.2).

One camera and a projector that always shows the same random-dot pattern, a known distance apart along the
camera's x axis. The projector is an inverse camera: the dot a surface point shows is the pattern pixel the point
projects to. The sensor keeps a *reference image*, the camera's image of the dots on a plane at a known distance
``Z0``; a dot on a surface at depth ``Z`` appears shifted along the baseline from where it is in the reference by
``f b (1/Z - 1/Z0)`` pixels (``f`` the focal length, ``b`` the baseline): the disparity against the reference is
inversely proportional to depth (:mod:`rangekit.stereo.dots` recovers it).

The rig is the active-stereo rig's left camera and dot projector (:func:`rangekit.sim.sensors.stereo.stereo_rig`),
the projector moved to ``baseline`` along the camera's x axis. Truth, for the camera: ``hit``, ``depth`` (camera
z), ``xyz`` (world), and ``visible`` (hit and lit by the projector: a dot can only be matched where one falls, the
rest of ``hit`` is the projector's shadow).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from rangekit.errors import InputError
from rangekit.formats.dots_capture import DOTS_KIND
from rangekit.geometry import axis_angle_to_R, make_T
from rangekit.io import atomic_save_npz, atomic_write_json, write_png
from rangekit.rig.rig_file import Rig, save_rig
from rangekit.sim.imaging.render import ImagingModel, ViewRenderer
from rangekit.sim.scene.objects import make_object
from rangekit.sim.scene.raycast import cast_view
from rangekit.sim.scene.scene import Scene
from rangekit.sim.sensors.stereo import STEREO_MODEL, speckle_pattern, stereo_rig
from rangekit.formats.sessions.files import RIG_FILE

__all__ = ["REFERENCE_DISTANCE_M", "DotsCapture", "dots_rig", "reference_scene", "render_dots",
           "write_dots_capture"]

#: The reference plane's distance from the camera (metres, along its axis): Kinect v1 kept its reference at
#: about a metre, inside its 0.8-4 m range.
REFERENCE_DISTANCE_M = 1.0


@dataclass(frozen=True, eq=False, repr=False)
class DotsCapture:
    """One simulated exposure of the dot sensor, its reference image, and the camera's exact truth.

    image : (H, W) uint8, the camera's image of the scene under the dots.
    reference : (H, W) uint8, its image of the dots on a plane facing it at ``reference_distance`` (its own noise).
    reference_distance : metres, the plane's distance along the camera's optical axis.
    hit, depth, xyz : (H, W) bool, (H, W) float64 camera z in metres, (H, W, 3) float64 world metres (NaN where
        not hit).
    visible : (H, W) bool, hit and lit by the projector.
    pattern : (Hp, Wp) float32 in [0, 1], the projected dots.
    seed : noise seed.
    """

    image: np.ndarray
    reference: np.ndarray
    reference_distance: float
    hit: np.ndarray
    depth: np.ndarray
    xyz: np.ndarray
    visible: np.ndarray
    pattern: np.ndarray
    seed: int

    def __repr__(self) -> str:
        H, W = self.image.shape
        return (f"DotsCapture({W}x{H}, reference at {self.reference_distance:.3f} m, visible "
                f"{int(self.visible.sum())} of {int(self.hit.sum())} hit pixels, seed={self.seed})")


def dots_rig(width: int = 640, height: int = 400, baseline: float = 0.075) -> Rig:
    """The dot sensor's rig: :func:`stereo_rig`'s left camera (world = its frame) and its dot projector
    (``2 width`` x ``2 height`` pattern pixels, 90 deg across), moved to ``baseline`` metres along the camera's +x
    (Kinect v1: 7.5 cm). ``cameras = (camera,)``."""
    base = stereo_rig(width, height, baseline)
    if not (np.isfinite(baseline) and baseline > 0):
        raise InputError(f"dots_rig: baseline must be > 0 metres, found {baseline!r}")
    camera, projector = base.cameras[0], base.projector
    moved = type(projector)(projector.K, projector.width, projector.height, projector.dist,
                            make_T(t=[float(baseline), 0.0, 0.0]), name="dot_projector")
    return Rig(cameras=(camera,), projector=moved)


def reference_scene(distance: float = REFERENCE_DISTANCE_M, camera=None) -> Scene:
    """A white plane facing the camera ``distance`` metres along its optical axis, wide enough to fill its view
    (the camera of ``camera``'s pose; default the world frame)."""
    if not (np.isfinite(distance) and distance > 0):
        raise InputError(f"reference_scene: distance must be > 0 metres, found {distance!r}")
    T_world_cam = np.eye(4) if camera is None else camera.T_world_cam
    side = 4.0 * distance
    wall = make_object("plane", width=side, height=side, albedo=0.8, name="reference") \
        .with_pose(T_world_cam @ make_T(axis_angle_to_R([1.0, 0.0, 0.0], np.pi), [0.0, 0.0, float(distance)]))
    return Scene((wall,))


def render_dots(scene: Scene, rig: Rig, *, reference_distance: float = REFERENCE_DISTANCE_M,
                model: ImagingModel = STEREO_MODEL, pattern: np.ndarray | None = None, seed: int = 0) -> DotsCapture:
    """Render the dot sensor's image of ``scene`` (in the rig's world), its reference image and the truth.

    ``pattern``: (Hp, Wp) the projector's dots (default ``speckle_pattern(Wp, Hp, seed=0)``: a property of the
    projector, not of ``seed``); ``seed``: the noise of the image, then the reference's, from one generator.
    """
    if len(rig.cameras) != 1 or rig.projector is None:
        raise InputError(f"render_dots: the rig needs one camera and the dot projector, found {len(rig.cameras)} "
                         f"camera(s) and projector={rig.projector is not None}")
    if model.colour:
        raise InputError("render_dots: the sensor's camera is monochrome; use ImagingModel(colour=False)")
    camera, proj = rig.cameras[0], rig.projector
    pattern = speckle_pattern(proj.width, proj.height, seed=0) if pattern is None else np.asarray(pattern, np.float32)
    if pattern.shape != (proj.height, proj.width):
        raise InputError(f"render_dots: pattern is {pattern.shape[1::-1]} (width, height) but the projector is "
                         f"{proj.width}x{proj.height}")
    g = cast_view(scene.world_mesh(), camera, proj)
    g_ref = cast_view(reference_scene(reference_distance, camera).world_mesh(), camera, proj)
    rng = np.random.default_rng(seed)
    image = ViewRenderer(g, model, proj.size).render(pattern, rng)
    reference = ViewRenderer(g_ref, model, proj.size).render(pattern, rng)
    return DotsCapture(image=image, reference=reference, reference_distance=float(reference_distance), hit=g.hit,
                       depth=g.depth, xyz=g.xyz, visible=g.hit & g.lit, pattern=pattern, seed=int(seed))


def write_dots_capture(capture: DotsCapture, rig: Rig, out_dir: str | Path, *,
                       model: ImagingModel | None = None) -> list[Path]:
    """Write a dot-sensor capture folder (every file atomically); returns ``[image.png, reference.png]``.

    Layout::

        image.png, reference.png   raw 8-bit images: the scene, the reference plane
        rig.json                   the rig (true calibration): cameras (camera,), projector = the dot projector
        capture.json               {"kind": "rangekit.dots/1", "reference_distance_m", "seed", "imaging"}
                                   (rangekit.formats.dots_capture)
        ground_truth.npz           depth (H, W) camera z m; xyz (H, W, 3) world m; hit, valid (= visible) (H, W)
                                   bool; T_world_cam (4, 4). NaN / False where undefined.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / "image.png", out / "reference.png"]
    write_png(paths[0], capture.image)
    write_png(paths[1], capture.reference)
    save_rig(rig, out / RIG_FILE)
    atomic_write_json(out / "capture.json", {"kind": DOTS_KIND, "reference_distance_m": capture.reference_distance,
                                             "seed": capture.seed,
                                             **({"imaging": asdict(model)} if model is not None else {})})
    atomic_save_npz(out / "ground_truth.npz", depth=capture.depth, xyz=capture.xyz, hit=capture.hit,
                    valid=capture.visible, T_world_cam=rig.cameras[0].T_world_cam)
    return paths
