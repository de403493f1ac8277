"""Simulated laser-plane calibration sessions: the board held where the line lasers cross it.

The lasers of :func:`rangekit.sim.laser.rig.laser_rig` are vertical sheets through the turntable axis, so a
board crosses both lines when it stands near the axis. :func:`laser_board_poses` draws such poses (board
centre near the axis, varied distance and height, tilted 10..40 deg in a random direction, rolled), each
kept when the camera sees the whole board (:func:`rangekit.sim.writers.calibration.pose_problem`) and every laser's
line runs across it (:func:`line_on_board`). :func:`render_board_pose` renders one pose's laser-off image
and one frame per laser with :class:`rangekit.sim.laser.frames.LaserView` (the board scene, no turntable).

Frames: world = the rig's (turntable frame), metres; board frame as in :mod:`rangekit.boards`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rangekit.boards import Board
from rangekit.camera import PinholeCamera, world_pixel_rays
from rangekit.errors import SceneError
from rangekit.geometry import axis_angle_to_R, make_T
from rangekit.rig.rig_file import Rig
from rangekit.sim.writers.calibration import board_scene, pose_problem
from rangekit.sim.laser.frames import LaserLook, LaserView
from rangekit.sim.scene.raycast import pixel_corners
from rangekit.sim.imaging.render import ImagingModel

__all__ = ["line_on_board", "laser_board_poses", "BoardLaserFrames", "render_board_pose", "CALIBRATION_LOOK",
           "turntable_board_scene_laser"]

#: Room light on while the board is calibrated (brighter than a scan's 0.12: the corners are found in the
#: laser-off image); a white square under the line stays below full scale (0.3 * 0.9 + 0.6 < 1).
CALIBRATION_LOOK = LaserLook(ambient=0.3)


def line_on_board(board: Board, T_world_board: np.ndarray, plane) -> float:
    """Length (metres) of the laser plane's line (``plane`` (4,) ``[n, d]``, world) inside the board's
    extent (margin included) at ``T_world_board``; 0 when it misses the board."""
    T = np.asarray(T_world_board, dtype=np.float64)
    p = np.asarray(plane, dtype=np.float64)
    a, b, _ = T[:3, :3].T @ p[:3]
    c = float(p[:3] @ T[:3, 3] + p[3])
    k = math.hypot(a, b)
    if k < 1e-12:
        return 0.0  # the board lies in (or parallel to) the plane: no line
    p0 = -c * np.array([a, b]) / k ** 2
    u = np.array([-b, a]) / k
    x0, y0, x1, y1 = board.extent
    lo, hi = -math.inf, math.inf
    for axis, (m0, m1) in enumerate(((x0, x1), (y0, y1))):
        if abs(u[axis]) < 1e-15:
            if not m0 <= p0[axis] <= m1:
                return 0.0
            continue
        t0, t1 = sorted(((m0 - p0[axis]) / u[axis], (m1 - p0[axis]) / u[axis]))
        lo, hi = max(lo, t0), min(hi, t1)
    return max(hi - lo, 0.0)


def laser_board_poses(rig: Rig, board: Board, n: int = 10, *, seed: int = 0,
                      depth: tuple[float, float] = (-0.06, 0.06), height: tuple[float, float] = (0.02, 0.10),
                      lateral: float = 0.02, tilt: tuple[float, float] = (math.radians(10.0), math.radians(40.0)),
                      roll: float = math.radians(20.0), min_line: float = 0.5, margin: float = 20.0,
                      max_tries: int = 5000) -> list[np.ndarray]:
    """``n`` board poses ``T_world_board`` (4, 4) for laser-plane calibration on ``rig`` (it needs lasers).

    Each draw (``numpy.random.default_rng(seed)``): the board centre at a point of the turntable axis at
    ``height`` metres above the table, moved ``depth`` metres horizontally towards the camera and up to
    ``lateral`` metres sideways; the board fronto-parallel to the camera, rolled by up to ``roll`` and tilted
    by an angle in ``tilt`` (radians) about a random in-plane axis. Kept when the camera sees the whole
    board ``margin`` px inside its image facing it, and each laser's line crosses the board over at least
    ``min_line`` x the board's shorter side.

    Raises
    ------
    SceneError : no lasers or no turntable, or fewer than ``n`` poses pass in ``max_tries`` draws.
    """
    if not rig.lasers or rig.T_world_table is None:
        raise SceneError("laser_board_poses: the rig needs lasers and a turntable (rangekit.sim.laser.rig)")
    rng = np.random.default_rng(seed)
    cam = rig.camera
    T_table = rig.T_world_table
    axis, foot = T_table[:3, 2], T_table[:3, 3]
    towards = cam.center - foot
    towards -= axis * (axis @ towards)
    towards /= np.linalg.norm(towards)
    side = np.cross(axis, towards)
    x0, y0, x1, y1 = board.extent
    c_board = np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.0])
    need = min_line * min(x1 - x0, y1 - y0)
    poses: list[np.ndarray] = []
    for _ in range(int(max_tries)):
        centre = foot + axis * rng.uniform(*height) + towards * rng.uniform(*depth) + \
            side * rng.uniform(-lateral, lateral)
        phi, theta, psi = rng.uniform(0, 2 * math.pi), rng.uniform(*tilt), rng.uniform(-roll, roll)
        R = cam.T_world_cam[:3, :3] @ axis_angle_to_R([math.cos(phi), math.sin(phi), 0.0], theta) @ \
            axis_angle_to_R([0.0, 0.0, 1.0], psi)
        T = make_T(R, centre - R @ c_board)
        if pose_problem(cam, board, T, margin=margin):
            continue
        if all(line_on_board(board, T, laser.plane) >= need for laser in rig.lasers):
            poses.append(T)
            if len(poses) == n:
                return poses
    raise SceneError(f"laser_board_poses: only {len(poses)} of {n} poses in {max_tries} draws with the whole board "
                     f"seen and every laser line crossing it; widen depth={depth} or height={height}")


@dataclass(frozen=True, eq=False)
class BoardLaserFrames:
    """One rendered board pose: ``off`` the laser-off image (the board's corners are found in it),
    ``frames`` one laser-on image per rig laser, ``T_world_board`` the true pose (for tests only: the
    calibration uses the pose found from the corners)."""

    off: np.ndarray
    frames: tuple[np.ndarray, ...]
    T_world_board: np.ndarray


_RAYS: dict = {}


def _camera_rays(camera: PinholeCamera) -> tuple:
    """(cam_rays, corner_rays) of ``camera`` for cast_view, cached for the last camera (poses share them;
    two cameras are kept: the laser poses' and the camera-calibration poses' may differ in resolution)."""
    key = (camera.K.tobytes(), camera.dist.tobytes(), camera.T_world_cam.tobytes(), camera.width, camera.height)
    if key not in _RAYS:
        if len(_RAYS) >= 2:
            _RAYS.pop(next(iter(_RAYS)))
        _RAYS[key] = (world_pixel_rays(camera), camera.rays(pixel_corners(camera)))
    return _RAYS[key]


def render_board_pose(rig: Rig, board: Board, T_world_board: np.ndarray, *, seed: int = 0,
                      imaging: ImagingModel | None = None, look: LaserLook = CALIBRATION_LOOK,
                      ambient_scale: int = 1, lasers: bool = True) -> BoardLaserFrames:
    """The board alone at ``T_world_board`` seen by ``rig``'s camera: laser off, then each laser on (none
    without ``lasers``: a camera-calibration view) (``ambient_scale``: :class:`LaserView`'s; 1 renders the
    board's texture at full resolution)."""
    cam = rig.camera
    if ambient_scale > 1:
        cam = cam.resized(max(cam.width // ambient_scale, 1), max(cam.height // ambient_scale, 1))
    cam_rays, corner_rays = _camera_rays(cam)
    view = LaserView(board_scene(board, T_world_board), rig, 0.0, imaging=imaging, look=look, seed=seed,
                     ambient_scale=ambient_scale, cam_rays=cam_rays, corner_rays=corner_rays)
    frames = tuple(view.frame(k).image for k in range(len(rig.lasers))) if lasers else ()
    return BoardLaserFrames(off=view.off(), frames=frames, T_world_board=np.asarray(T_world_board, dtype=np.float64))


def turntable_board_scene_laser(rig: Rig, board: Board, *, tilt_deg: float = 20.0, offset: float = 0.04):
    """``board`` standing on the turntable disc, leaning back by ``tilt_deg`` and facing the camera (a laser rig
    has no projector): its bottom edge's middle ``offset`` metres behind the turntable axis, on the far side from
    the camera; it rides on the turntable, so a turntable angle turns it about the axis and both laser lines
    cross it for angles of about -30..+30 deg (the lasers of :func:`rangekit.sim.laser.rig.laser_rig`). The scene
    holds the turntable disc too (the table top the lines also light). As
    :func:`rangekit.sim.writers.calibration.turntable_board_scene` for a projector-camera rig."""
    from rangekit.geometry import apply_T, compose, invert_T
    from rangekit.sim.scene.objects import board_object, turntable_disc
    from rangekit.sim.scene.scene import Scene

    if rig.T_world_table is None:
        raise SceneError("turntable_board_scene_laser: the rig needs a turntable (T_world_table)")
    c = apply_T(invert_T(rig.T_world_table), rig.camera.center[None])[0, :2]
    h = c / np.linalg.norm(c)
    t = math.radians(tilt_deg)
    x_axis = np.array([-h[1], h[0], 0.0])
    y_axis = np.array([math.sin(t) * h[0], math.sin(t) * h[1], -math.cos(t)])   # down the board
    R = np.column_stack([x_axis, y_axis, np.cross(x_axis, y_axis)])
    x0, _, x1, y1 = board.extent
    bottom = np.array([-offset * h[0], -offset * h[1], 0.0])
    T_table_board = make_T(R, bottom - R @ np.array([(x0 + x1) / 2, y1, 0.0]))
    obj = board_object(board).with_pose(compose(rig.T_world_table, T_table_board))
    return Scene((obj, turntable_disc().with_pose(rig.T_world_table)))
