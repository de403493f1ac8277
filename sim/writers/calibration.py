"""Simulated calibration sessions: hand-held board poses and boards standing on the turntable, and board poses
recorded as another tool records them (:func:`write_layout_poses`: its frames, under its file names).

Poses are ``T_world_board`` (4, 4): board frame as in :mod:`rangekit.boards` (corners in z = 0, printed
side towards -z), world frame the rig's. ``board_scene`` and ``turntable_board_scene`` build the
:class:`~rangekit.sim.scene.scene.Scene` to hand to :meth:`~rangekit.sim.devices.sim_rig.SimRig.set_scene`.
"""

from __future__ import annotations

import dataclasses
from collections import Counter
from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

from rangekit.boards import Board
from rangekit.camera import PinholeCamera
from rangekit.errors import SceneError
from rangekit.io import atomic_write_bytes
from rangekit.geometry import apply_T, axis_angle_to_R, compose, invert_T, make_T
from rangekit.rig.rig_file import Rig
from rangekit.sim.scene.objects import board_object, turntable_disc
from rangekit.sim.scene.scene import Scene

__all__ = ["board_poses", "board_scene", "turntable_board_scene", "board_outline", "pose_problem",
           "write_layout_poses"]


def board_outline(board: Board, *, per_edge: int = 16) -> np.ndarray:
    """(4 * per_edge + n_corners, 3) board-frame points that must be seen for the whole board to be
    visible: the outer edge of the margin (``per_edge`` samples per side) and every inner corner."""
    x0, y0, x1, y1 = board.extent
    t = np.linspace(0.0, 1.0, per_edge, endpoint=False)
    edges = np.concatenate([
        np.column_stack([x0 + t * (x1 - x0), np.full_like(t, y0)]),
        np.column_stack([np.full_like(t, x1), y0 + t * (y1 - y0)]),
        np.column_stack([x1 - t * (x1 - x0), np.full_like(t, y1)]),
        np.column_stack([np.full_like(t, x0), y1 - t * (y1 - y0)])])
    edges = np.column_stack([edges, np.zeros(len(edges))])
    return np.concatenate([edges, board.object_points()])


def pose_problem(device: PinholeCamera, board: Board, T_world_board: np.ndarray, *, margin: float = 20.0,
                 max_incidence: float = np.radians(60.0)) -> str:
    """Why ``device`` does not see the whole printed side of the board at ``T_world_board``, or "".

    Checks that every point of :func:`board_outline` projects at least ``margin`` pixels inside the image
    (pixel centres at integers, so the image spans [-0.5, size - 0.5]) and that the angle between the
    printed side's normal and the direction from the board centre to the device is below
    ``max_incidence`` radians.
    """
    x0, y0, x1, y1 = board.extent
    centre = apply_T(T_world_board, np.array([[(x0 + x1) / 2, (y0 + y1) / 2, 0.0]]))[0]
    normal = -np.asarray(T_world_board)[:3, 2]  # the printed side faces -z
    to_dev = device.center - centre
    cos = normal @ to_dev / np.linalg.norm(to_dev)
    if not cos > np.cos(max_incidence):
        return (f"{device.name}: printed side at {np.degrees(np.arccos(np.clip(cos, -1, 1))):.0f} deg from the "
                f"direction to it (max {np.degrees(max_incidence):.0f})")
    uv = device.project(apply_T(T_world_board, board_outline(board)))
    lo = margin - 0.5
    inside = np.all(np.isfinite(uv), axis=1) & (uv[:, 0] >= lo) & (uv[:, 1] >= lo) & \
        (uv[:, 0] <= device.width - 1 - lo) & (uv[:, 1] <= device.height - 1 - lo)
    if not np.all(inside):
        return f"{device.name}: {np.count_nonzero(~inside)} board points outside the image (margin {margin:g} px)"
    return ""


def board_poses(rig: Rig, board: Board, n: int = 15, *, seed: int | np.random.Generator = 0,
                distance: tuple[float, float] = (0.42, 0.58), margin: float = 20.0,
                tilt: tuple[float, float] = (np.radians(10.0), np.radians(45.0)),
                roll: float = np.radians(30.0), max_incidence: float = np.radians(60.0),
                max_tries: int = 20000) -> list[np.ndarray]:
    """Realistic hand-held calibration poses of ``board``, seen whole by the camera and the projector.

    Each pose is drawn as follows (rejection sampling with ``numpy.random.default_rng(seed)``): a pixel
    uniform over the camera image and a distance uniform in ``distance`` (metres, camera centre to
    board centre) give the board centre; the board starts fronto-parallel to the camera (board axes =
    camera axes, printed side towards it), turns in-plane by an angle uniform in ``[-roll, roll]`` and
    tilts by an angle uniform in ``tilt`` about an in-plane axis of uniform direction (radians). A pose is
    kept when, for the camera and the projector (:func:`pose_problem`), the whole board (its margin and
    every corner) is at least ``margin`` pixels inside the image and the printed side faces the device
    (normal within ``max_incidence`` of the direction to it).

    Returns
    -------
    list of n (4, 4) float64 ``T_world_board``.

    Raises
    ------
    SceneError
        If the rig has no projector, or fewer than ``n`` poses pass in ``max_tries`` draws; the message
        names the constraint that rejected most draws.
    """
    if rig.projector is None:
        raise SceneError("board_poses: the rig has no projector; both the camera and the projector must see "
                         "the board")
    if not (0 < distance[0] <= distance[1]):
        raise SceneError(f"board_poses: distance must be (near, far) metres with 0 < near <= far, found {distance}")
    rng = np.random.default_rng(seed)
    cam, proj = rig.camera, rig.projector
    x0, y0, x1, y1 = board.extent
    c_board = np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.0])
    poses: list[np.ndarray] = []
    rejected: Counter = Counter()
    for _ in range(int(max_tries)):
        uv = rng.uniform([-0.5, -0.5], [cam.width - 0.5, cam.height - 0.5])[None]
        d = rng.uniform(*distance)
        phi, theta = rng.uniform(0.0, 2 * np.pi), rng.uniform(*tilt)
        psi = rng.uniform(-roll, roll)
        ray = cam.rays(uv)[1][0]
        R_cam_board = axis_angle_to_R([np.cos(phi), np.sin(phi), 0.0], theta) @ axis_angle_to_R([0, 0, 1.0], psi)
        R_world_board = cam.T_world_cam[:3, :3] @ R_cam_board
        T = make_T(R_world_board, cam.center + d * ray - R_world_board @ c_board)
        problem = pose_problem(cam, board, T, margin=margin, max_incidence=max_incidence) or \
            pose_problem(proj, board, T, margin=margin, max_incidence=max_incidence)
        if problem:
            rejected[problem.split(":")[0] + ": " + ("faces away" if "deg from" in problem else "outside image")] += 1
            continue
        poses.append(T)
        if len(poses) == n:
            return poses
    worst = ", ".join(f"{k} ({v} draws)" for k, v in rejected.most_common(2))
    raise SceneError(f"board_poses: only {len(poses)} of {n} poses in {max_tries} draws; most rejected by {worst}. "
                     f"Widen distance={distance} (a smaller board fits closer), reduce margin={margin} px, or "
                     f"use a smaller board")


def board_scene(board: Board, T_world_board: np.ndarray) -> Scene:
    """A scene holding only ``board`` at ``T_world_board`` (not on the turntable, no table)."""
    obj = board_object(board)
    return Scene((dataclasses.replace(obj, T_world_obj=T_world_board, on_turntable=False),))


def turntable_board_scene(rig: Rig, board: Board, *, tilt_deg: float = 20.0, offset: float = 0.04) -> Scene:
    """``board`` standing on the turntable disc, leaning back, facing the camera and projector.

    The board's bottom edge (its ``y = y1`` side, the margin's outer edge) lies on the table top with its
    middle ``offset`` metres from the turntable axis, on the far side from the devices; it leans back
    from vertical by ``tilt_deg`` degrees (a human-typed angle; 20 deg: the printed side looks up towards
    a camera 25 deg above the table) and is turned about the axis to face the bisector of the camera's
    and the projector's directions. The board rides on the turntable (``on_turntable=True``): ``SimRig``
    turntable angles turn it about the axis, its centre about 7 cm off the axis (defaults, 10 x 7 board
    of 2 cm squares). On the default rig, with the defaults, the whole board (margin and corners) stays
    at least 20 px inside the camera and projector images, facing both within 60 deg, for turntable
    angles from -45 to +60 degrees (checked in tests/sim/test_boards.py for -40..+40). The scene also holds
    the turntable disc (radius 0.15 m), which the board's footprint fits on.

    Raises
    ------
    SceneError
        If the rig has no turntable or no projector.
    """
    if rig.T_world_table is None or rig.projector is None:
        raise SceneError("turntable_board_scene: the rig needs a turntable (T_world_table) and a projector")
    T_table_world = invert_T(rig.T_world_table)
    h = np.zeros(2)
    for dev in (rig.camera, rig.projector):
        c = apply_T(T_table_world, dev.center[None])[0, :2]
        h += c / np.linalg.norm(c)
    h /= np.linalg.norm(h)
    t = np.radians(tilt_deg)
    x_axis = np.array([-h[1], h[0], 0.0])
    y_axis = np.array([np.sin(t) * h[0], np.sin(t) * h[1], -np.cos(t)])  # down the board
    R = np.column_stack([x_axis, y_axis, np.cross(x_axis, y_axis)])
    x0, _, x1, y1 = board.extent
    bottom = np.array([-offset * h[0], -offset * h[1], 0.0])
    T_table_board = make_T(R, bottom - R @ np.array([(x0 + x1) / 2, y1, 0.0]))
    obj = board_object(board).with_pose(compose(rig.T_world_table, T_table_board))
    disc = turntable_disc().with_pose(rig.T_world_table)
    return Scene((obj, disc))


def write_layout_poses(folder: str | Path, rig: Rig, board: Board, poses: Sequence[np.ndarray], layout, *,
                       seed: int = 0, imaging=None) -> list[Path]:
    """Board poses recorded as another tool records them: per pose a folder ``pose_01``, ``pose_02``, ... in
    ``folder`` holding the frames that tool projects (:func:`rangekit.formats.layouts.tool_frames` of
    ``layout``, a :class:`~rangekit.formats.layouts.CaptureLayout`, for ``rig``'s projector) under its own file
    names, as the simulated rig captures them (:class:`rangekit.sim.devices.sim_rig.SimRig`, ``seed``, ``imaging``
    an :class:`~rangekit.sim.imaging.render.ImagingModel` or the default). ``poses``: ``T_world_board`` (4, 4)
    each (:func:`board_poses`). Returns the pose folders, in order; each file is written atomically.
    """
    from rangekit.formats.layouts import tool_frames
    from rangekit.sim.devices.sim_rig import SimRig

    if rig.projector is None:
        raise SceneError("write_layout_poses: the rig has no projector to project the layout's frames")
    frames = tool_frames(layout, rig.projector.width, rig.projector.height)
    first = layout.first_index
    sim = SimRig(board_scene(board, poses[0]), rig, seed=seed, **({"imaging": imaging} if imaging else {}))
    folders = []
    for i, T in enumerate(poses):
        sim.set_scene(board_scene(board, T))
        pose_folder = Path(folder) / f"pose_{i + 1:02d}"
        pose_folder.mkdir(parents=True, exist_ok=True)
        for k, image in enumerate(sim.capture_sequence(frames)):
            name = layout.file_name.format(first + k, index=first + k, camera=1)
            ok, data = cv2.imencode(Path(name).suffix, image)
            if not ok:
                raise SceneError(f"write_layout_poses: OpenCV cannot encode {name}")
            atomic_write_bytes(pose_folder / name, data.tobytes())
        folders.append(pose_folder)
    return folders
