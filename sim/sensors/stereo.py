"""A simulated active-stereo sensor: two cameras and a random-dot projector (OAK-D-Pro-like).

Fusiello ch. 13.2.1: a stereo pair cannot match a textureless surface, so an active stereo sensor projects
a fixed random-dot ("speckle") pattern that gives every surface patch a unique texture. Here the dot
projector is a :class:`~rangekit.camera.PinholeCamera` showing :func:`speckle_pattern`, and each camera
image is rendered by :class:`~rangekit.sim.imaging.render.ViewRenderer` (projector falloff, ambient light, blur,
shot and read noise, 8-bit quantisation; see docs/simulator.md).

Truth comes with each capture, for the **left** camera (world = left camera frame for
:func:`stereo_rig`, but the code only reads ``T_world_cam``):

* ``hit``, ``depth`` (camera z), ``range`` (along the ray), ``xyz`` (world), exact to double precision;
* ``visible``: hit by the left camera **and** seen, unoccluded, by the right camera (the ray cast of
  :func:`~rangekit.sim.scene.raycast.cast_view` with the right camera in the projector's place). These are
  the only pixels a stereo matcher can match; the rest of ``hit`` is the occluded band;
* ``lit``: lit by the dot projector (no dots fall on the rest: the projector's own shadow).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.errors import InputError
from rangekit.geometry import axis_angle_to_R, make_T, rotvec_to_R
from rangekit.io import atomic_save_npz, atomic_write_json, write_png
from rangekit.rig.rig_file import Rig, save_rig
from rangekit.sim.writers.capture import _colourise
from rangekit.sim.scene.objects import make_object
from rangekit.sim.scene.raycast import cast_view
from rangekit.sim.imaging.render import ImagingModel, ViewRenderer
from rangekit.sim.scene.scene import Scene
from rangekit.formats.sessions.files import RIG_FILE

__all__ = ["STEREO_MODEL", "StereoCapture", "stereo_rig", "speckle_pattern", "stereo_scene", "render_stereo",
           "write_stereo_capture"]

#: Default sensor: strong room light (a dot-less image is a uniform grey, not black), a slightly defocused
#: dot projector, otherwise :class:`ImagingModel`'s defaults (8 bits, shot + read noise).
STEREO_MODEL = ImagingModel(gain=2.0, ambient=0.1, projector_blur=1.2, camera_blur=0.5)


@dataclass(frozen=True, eq=False, repr=False)
class StereoCapture:
    """One simulated active-stereo exposure and the exact truth of its left camera.

    left, right : (H, W) uint8 raw images of the left and right camera.
    hit : (H, W) bool, left pixels whose ray meets a surface.
    depth : (H, W) float64 left-camera z of the hit, metres; NaN where not ``hit``.
    range : (H, W) float64 distance from the left optical centre to the hit, metres; NaN where not ``hit``.
    xyz : (H, W, 3) float64 world hit points, metres; NaN where not ``hit``.
    visible : (H, W) bool, ``hit`` and seen unoccluded by the right camera (inside its image, facing it,
        nothing in between): the pixels a matcher can possibly match.
    lit : (H, W) bool, ``hit`` and lit by the dot projector.
    pattern : (Hp, Wp) float32 in [0, 1], the projected image (all zero when ``dots`` is False).
    dots : bool, whether the dot projector was on.
    seed : int, noise seed; the same seed, scene and rig give the same bytes.
    object_names : names of the scene objects.
    """

    left: np.ndarray
    right: np.ndarray
    hit: np.ndarray
    depth: np.ndarray
    range: np.ndarray
    xyz: np.ndarray
    visible: np.ndarray
    lit: np.ndarray
    pattern: np.ndarray
    dots: bool
    seed: int
    object_names: tuple[str, ...]

    def __repr__(self) -> str:
        H, W = self.left.shape[:2]
        d = self.depth[self.hit]
        return (f"StereoCapture({W}x{H}, dots={self.dots}, seed={self.seed}, hit={int(self.hit.sum())}, "
                f"visible={int(self.visible.sum())}, depth_m=[{d.min():.3f}, {d.max():.3f}])")


def stereo_rig(width: int = 640, height: int = 400, baseline: float = 0.075) -> Rig:
    """An OAK-D-Pro-like active stereo rig: two global-shutter cameras and a dot projector between them.

    * Cameras: ``fx = fy = 440 px`` at 640 wide (HFOV 72 deg), scaled with ``width`` (same field of view),
      principal points a few pixels off centre, mild and different barrel distortion.
    * World = left camera frame (``T_world_cam = I``). The right camera sits ``baseline`` metres along +x
      (plus 0.3 mm / -0.2 mm along y / z) and is rotated by about 0.3 deg: a realistic assembly error, so
      rectification has to do real work.
    * Projector: ``2 * width`` x ``2 * height`` pattern pixels, HFOV 90 deg (covers both views from 0.3 m
      on), at x = 0.45 * baseline, looking along +z. ``cameras = (left, right)``.
    """
    if int(width) != width or int(height) != height or width < 32 or height < 32:
        raise InputError(f"stereo_rig: width and height must be integers >= 32 pixels, found {width}x{height}")
    if not (np.isfinite(baseline) and baseline > 0):
        raise InputError(f"stereo_rig: baseline must be > 0 metres, found {baseline!r}")
    width, height = int(width), int(height)
    s = width / 640.0
    f = 440.0 * s

    def K(dx: float, dy: float, scale_f: float = 1.0) -> np.ndarray:
        return np.array([[f * scale_f, 0.0, (width - 1) / 2 + dx * s],
                         [0.0, f * scale_f, (height - 1) / 2 + dy * s], [0.0, 0.0, 1.0]])

    left = PinholeCamera(K(3.1, -2.4), width, height, dist=[-0.045, 0.021, 0.0004, -0.0003, 0.0],
                         name="left")
    R = rotvec_to_R(np.radians([0.12, -0.25, 0.09]))  # 0.29 deg in all
    right = PinholeCamera(K(-2.2, 1.7, 1.003), width, height, dist=[-0.052, 0.026, -0.0002, 0.0005, 0.0],
                          T_world_cam=make_T(R, [baseline, 0.0003, -0.0002]), name="right")
    Wp, Hp = 2 * width, 2 * height
    fp = Wp / 2.0  # HFOV 90 deg
    projector = PinholeCamera(np.array([[fp, 0.0, (Wp - 1) / 2], [0.0, fp, (Hp - 1) / 2], [0.0, 0.0, 1.0]]),
                              Wp, Hp, T_world_cam=make_T(t=[0.45 * baseline, 0.0, 0.0]), name="dot_projector")
    return Rig(cameras=(left, right), projector=projector)


def speckle_pattern(width: int, height: int, *, density: float = 0.2, dot_radius: float = 1.5,
                    seed: int = 0) -> np.ndarray:
    """(height, width) float32 random-dot image in [0, 1]: bright anti-aliased discs on black.

    ``density`` is the expected fraction of the image the dots cover (before overlaps): ``density * W * H /
    (pi r^2)`` dot centres are drawn uniformly on a 1/4-pixel grid. ``dot_radius`` in pattern pixels. Dots are
    drawn at 4x resolution and area-averaged, so partly covered pixels get their covered fraction.
    """
    if int(width) != width or int(height) != height or width < 1 or height < 1:
        raise InputError(f"speckle_pattern: size must be positive integers, found {width}x{height}")
    if not (0 < density <= 1):
        raise InputError(f"speckle_pattern: density must be in (0, 1], found {density!r}")
    if not (0.25 <= dot_radius <= 50):
        raise InputError(f"speckle_pattern: dot_radius must be in [0.25, 50] pattern pixels, found {dot_radius!r}")
    rng = np.random.default_rng(seed)
    ss = 4
    W4, H4 = int(width) * ss, int(height) * ss
    n = int(round(density * width * height / (np.pi * dot_radius ** 2)))
    fine = np.zeros((H4, W4), np.uint8)
    fine.reshape(-1)[rng.choice(H4 * W4, size=n, replace=False)] = 255
    r = dot_radius * ss
    k = int(np.ceil(r - 0.5))
    yy, xx = np.mgrid[-k:k + 1, -k:k + 1]
    disc = (xx ** 2 + yy ** 2 <= r ** 2).astype(np.uint8)
    fine = cv2.dilate(fine, disc)
    out = cv2.resize(fine.astype(np.float32) / 255.0, (int(width), int(height)), interpolation=cv2.INTER_AREA)
    return np.clip(out, 0.0, 1.0).astype(np.float32)


def stereo_scene() -> Scene:
    """Textureless test scene in the left camera frame (metres): everything white (albedo 0.8).

    A box (20 x 16 x 16 cm, turned 30 deg about the vertical) centred 0.75 m ahead and 12 cm to the left,
    a sphere of radius 9 cm at 0.70 m, 14 cm to the right, and a 2 x 1.5 m wall at 1.10 m behind them.
    Nothing is textured: without the dots both images are a flat grey.
    """
    wall = make_object("plane", width=2.0, height=1.5, albedo=0.8, name="wall") \
        .with_pose(make_T(axis_angle_to_R([1.0, 0.0, 0.0], np.pi), [0.0, 0.0, 1.10]))
    cube = make_object("box", extents=(0.20, 0.16, 0.16), albedo=0.8, name="box") \
        .with_pose(make_T(axis_angle_to_R([0.0, 1.0, 0.0], np.radians(30.0)) @
                          axis_angle_to_R([1.0, 0.0, 0.0], np.radians(-10.0)), [-0.12, 0.03, 0.75]))
    ball = make_object("sphere", radius=0.09, albedo=0.8, name="sphere").with_pose(make_T(t=[0.14, -0.02, 0.70]))
    return Scene((cube, ball, wall))


def render_stereo(scene: Scene, rig: Rig, *, dots: bool = True, model: ImagingModel = STEREO_MODEL,
                  pattern: np.ndarray | None = None, seed: int = 0) -> StereoCapture:
    """Render the left and right images of an active stereo rig, and the left camera's truth.

    Parameters
    ----------
    scene : objects in the rig's world frame.
    rig : ``cameras = (left, right)`` and ``projector`` = the dot projector (:func:`stereo_rig`).
    dots : project ``pattern`` (True) or nothing (False: the images show only ambient light and noise).
    model : sensor model; its ``ambient`` sets the grey level without dots. Must be monochrome.
    pattern : (Hp, Wp) image for the projector; default ``speckle_pattern(Wp, Hp, seed=0)`` (the dot
        pattern is a fixed property of the projector, independent of ``seed``).
    seed : noise seed; left and right noise are drawn from one ``default_rng(seed)``, left first.

    Raises
    ------
    InputError
        If the rig does not have two cameras of the same size and a projector, or the model is colour.
        :class:`~rangekit.errors.SceneError` if the left camera sees nothing.
    """
    if len(rig.cameras) != 2 or rig.projector is None:
        raise InputError(f"render_stereo: the rig needs cameras=(left, right) and a dot projector, found "
                         f"{len(rig.cameras)} camera(s) and projector={rig.projector is not None}")
    left, right = rig.cameras
    if left.size != right.size:
        raise InputError(f"render_stereo: left camera is {left.width}x{left.height} but right is "
                         f"{right.width}x{right.height}; a stereo pair needs one size")
    if model.colour:
        raise InputError("render_stereo: the stereo cameras are monochrome; use ImagingModel(colour=False)")
    proj = rig.projector
    if pattern is None:
        pattern = speckle_pattern(proj.width, proj.height, seed=0)
    pattern = np.asarray(pattern, dtype=np.float32)
    if pattern.shape != (proj.height, proj.width):
        raise InputError(f"render_stereo: pattern is {pattern.shape[1::-1]} (width, height) but the projector "
                         f"{proj.name!r} is {proj.width}x{proj.height}")
    shown = pattern if dots else np.zeros_like(pattern)
    mesh = scene.world_mesh()
    g_left = cast_view(mesh, left, proj)
    g_right = cast_view(mesh, right, proj)
    seen_by_right = cast_view(mesh, left, right).lit  # right camera in the projector's place
    rng = np.random.default_rng(seed)
    img_l = ViewRenderer(g_left, model, proj.size).render(shown, rng)
    img_r = ViewRenderer(g_right, model, proj.size).render(shown, rng)
    return StereoCapture(left=img_l, right=img_r, hit=g_left.hit, depth=g_left.depth, range=g_left.range,
                         xyz=g_left.xyz, visible=g_left.hit & seen_by_right, lit=g_left.lit, pattern=shown,
                         dots=bool(dots), seed=int(seed), object_names=g_left.object_names)


def write_stereo_capture(capture: StereoCapture, rig: Rig, out_dir: str | Path, *,
                         model: ImagingModel | None = None) -> list[Path]:
    """Write a stereo capture folder (every file atomically) and return the image paths (left, right).

    Layout::

        left.png, right.png   raw 8-bit images
        rig.json              the rig (true calibration): cameras (left, right), projector = dot projector
        capture.json          {"kind": "rangekit.sim.stereo/1", "dots", "seed", "objects", "imaging"}
        ground_truth.npz      left camera truth: depth (H, W) camera z in m; range (H, W) m; xyz (H, W, 3)
                              world m; hit (H, W) bool; valid (H, W) bool (= visible: seen by both cameras);
                              T_world_cam (4, 4) of the left camera. NaN / False where undefined.
        preview.png           left, right, true depth, visible mask side by side
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / "left.png", out / "right.png"]
    write_png(paths[0], capture.left)
    write_png(paths[1], capture.right)
    save_rig(rig, out / RIG_FILE)
    atomic_write_json(out / "capture.json", {
        "kind": "rangekit.sim.stereo/1", "dots": capture.dots, "seed": capture.seed,
        "objects": list(capture.object_names), **({"imaging": asdict(model)} if model is not None else {})})
    atomic_save_npz(out / "ground_truth.npz", depth=capture.depth, range=capture.range, xyz=capture.xyz,
                    hit=capture.hit, valid=capture.visible, T_world_cam=rig.cameras[0].T_world_cam)
    write_png(out / "preview.png", _preview(capture))
    return paths


def _preview(capture: StereoCapture, width: int = 480) -> np.ndarray:
    """(h, 4 * width, 3) uint8 RGB strip: left, right, true depth (turbo), visible mask."""
    def grey(img: np.ndarray) -> np.ndarray:
        return np.repeat(img[:, :, None], 3, axis=2)

    panels = [grey(capture.left), grey(capture.right), _colourise(capture.depth, capture.hit),
              grey((capture.visible * 255).astype(np.uint8))]
    H, W = capture.hit.shape
    h = int(round(H * width / W))
    return np.hstack([cv2.resize(p, (width, h), interpolation=cv2.INTER_AREA) for p in panels])
