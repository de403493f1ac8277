"""Laser-plane calibration with real (or simulated) devices: the person places the board, rangekit switches
the lasers and captures, the planes are fitted with the rig's calibrated camera.

The device-independent work behind ``rangekit calibrate --lasers --rig RIG.json``: ``devices`` has a
``camera`` (:class:`rangekit.rig.devices.Camera`) and a ``turntable`` board with ``laser(n, on)`` (Horus
``M71T<n>``/``M70T<n>``, FabScan; :class:`rangekit.sim.devices.sim_rig.SimRig` in tests). For each of ``n_poses``
poses: ``ask(prompt)`` (the person places the board; pose hints as :mod:`rangekit.app.calibrate`'s), the
laser-off frame, then for each laser (rig file order) its ``switch`` on, one frame, off: never two lasers
on at once. Every laser is switched off before the first pose and again at the end, also on an error or
Ctrl-C (KeyboardInterrupt from ``ask``). The board pose comes from its corners by PnP with the rig's camera
(intrinsics and ``T_world_cam``), the lines are triangulated on the board and fitted per laser
(:func:`rangekit.app.laser.calibration.fit_laser_planes`); a pose whose board is not found or whose line
misses the board is rejected by name ("board pose 3: ...", "laser0: board pose 3: ...").

Frames: the rig's world, metres.
"""

from __future__ import annotations

import math
import time
from dataclasses import replace
from typing import Callable

import numpy as np

from rangekit.app.laser.calibration import LaserCalibration, fit_laser_planes, pnp_board_poses, pose_lines
from rangekit.boards import Board
from rangekit.errors import ConfigError, DeviceError, UsageError
from rangekit.progress import call_progress
from rangekit.rig.rig_file import Rig, template_rig

__all__ = ["LASER_POSE_HINTS", "check_laser_rig", "calibrate_lasers_on_devices"]

#: Where to hold the board for laser pose i (cycled): every line must cross the board, so it stays near
#: the turntable axis where the light sheets meet, and turns so that the lines cross it at varied angles.
LASER_POSE_HINTS = ("on the turntable's axis, facing the camera, tilted ~20 deg to the left",
                    "on the axis, tilted ~20 deg to the right", "on the axis, top edge tilted ~30 deg away",
                    "on the axis, bottom edge tilted ~30 deg away", "on the axis, turned ~20 deg in its plane",
                    "a few cm closer to the camera, tilted ~30 deg to the left",
                    "a few cm further away, tilted ~30 deg to the right", "a few cm higher, tilted down",
                    "a few cm lower, tilted up", "on the axis, turned ~-20 deg in its plane, tilted ~15 deg away")


def _switches(rig: Rig) -> list[int]:
    """The board's number of each laser (rig file ``switch``, default its position + 1, as the scan does)."""
    return [laser.switch if laser.switch is not None else k + 1 for k, laser in enumerate(rig.lasers)]


def check_laser_rig(rig: Rig, *, where: str = "rig file") -> None:
    """ConfigError unless ``rig`` (read from ``where``) can calibrate its lasers on hardware: it has
    ``lasers``, a calibrated camera (not the template's placeholder intrinsics), and ``devices`` naming a
    camera and the turntable board that switches the lasers. Nothing is opened or moved."""
    if not rig.lasers:
        raise ConfigError(f"{where}: lasers: expected a list of the rig's line lasers (each with its 'switch' "
                          "number on the turntable board and a rough 'plane'), found none; add them as "
                          "docs/rig.md ('lasers[]: line lasers') shows, then run rangekit calibrate --lasers")
    placeholder = template_rig()["cameras"][0]
    cam = rig.camera
    if np.array_equal(cam.K, placeholder["K"]) and not np.any(cam.dist):
        raise ConfigError(f"{where}: cameras[0] ({cam.name!r}) has the template's placeholder intrinsics (K "
                          f"{placeholder['K']}, no distortion), expected a calibrated camera: calibrate it first "
                          "(rangekit calibrate --rig RIG.json --out RIG.json, or the depthai factory calibration, "
                          "docs/rig.md)")
    devices = rig.devices or {}
    for key, what in (("camera", "a camera (type depthai)"),
                      ("turntable", "the turntable board that switches the lasers (protocol horus or fabscan)")):
        if not isinstance(devices.get(key), dict):
            raise ConfigError(f"{where}: devices.{key}: expected {what}, found "
                              f"{'nothing' if devices.get(key) is None else repr(devices.get(key))}; laser "
                              "calibration captures the board lit by each laser (docs/laser.md)")


def _all_off(board, switches: list[int]) -> None:
    """Every laser off; each switch is tried even if another fails (the first failure is raised after)."""
    first = None
    for n in switches:
        try:
            board.laser(n, False)
        except DeviceError as exc:
            first = first or exc
    if first is not None:
        raise first


def _capture(camera, rig: Rig, what: str) -> np.ndarray:
    image = np.asarray(camera.capture())
    cam = rig.camera
    if image.shape[:2] != (cam.height, cam.width):
        raise ConfigError(f"the camera's {what} is {image.shape[1]}x{image.shape[0]} px, but the rig file's "
                          f"cameras[0] is {cam.width}x{cam.height}: capture at the calibrated size")
    return image


def calibrate_lasers_on_devices(devices, rig: Rig, *, n_poses: int = 10, ask: Callable[[str], object] = input,
                                board: Board | None = None, progress: Callable | None = None,
                                min_points: int = 20, where: str = "rig file") -> LaserCalibration:
    """Calibrate every laser plane of ``rig`` from ``n_poses`` board poses placed by a person (module doc).

    Parameters
    ----------
    devices : ``camera`` (captures) and ``turntable`` (``laser(n, on)``), e.g. ``open_rig_devices(rig)``.
    rig : the rig file's rig: its calibrated camera finds the board poses; its lasers' ``switch`` numbers
        switch them (their planes may be rough guesses: they are replaced).
    n_poses : board poses (>= 2).
    ask : shows a prompt and returns once the board is in place (``input``); may raise KeyboardInterrupt.
    board : the calibration board (default ``Board()``: 10 x 7 squares of 20 mm).
    min_points : line points on the board below which a pose is rejected for that laser.

    Returns
    -------
    :class:`LaserCalibration` (``errors``/``truth`` None): ``rig`` is ``rig`` with the fitted planes.

    Raises
    ------
    ConfigError : no lasers, an uncalibrated camera, no camera or laser switch (before anything moves).
    CalibrationError : a laser's line is on too few poses, or its lines are collinear (named).
    """
    t0 = time.perf_counter()
    if isinstance(n_poses, bool) or not isinstance(n_poses, int) or n_poses < 2:
        raise UsageError(f"--laser-poses must be at least 2 (two board lines fix a plane), found {n_poses!r}")
    check_laser_rig(rig, where=where)
    table = getattr(devices, "turntable", None)
    if getattr(devices, "camera", None) is None or table is None or not callable(getattr(table, "laser", None)):
        raise ConfigError(f"{where}: laser calibration needs a camera and a turntable board with laser switches; "
                          f"found camera {type(getattr(devices, 'camera', None)).__name__}, turntable "
                          f"{type(table).__name__}")
    board = board if board is not None else Board()
    switches = _switches(rig)
    names = [f"board pose {i + 1}" for i in range(n_poses)]
    views, rejected = [], []
    _all_off(table, switches)
    try:
        for i in range(n_poses):
            call_progress(progress, "laser calibration: board poses", i, n_poses)
            ask(f"laser pose {i + 1}/{n_poses}: hold the {board.cols}x{board.rows} board still, "
                f"{LASER_POSE_HINTS[i % len(LASER_POSE_HINTS)]}, wholly in view with every laser line across it; "
                "press Enter to capture ")
            off = _capture(devices.camera, rig, "laser-off image")
            frames = []
            for n in switches:
                table.laser(n, True)
                try:
                    frames.append(_capture(devices.camera, rig, f"image with laser {n} on"))
                finally:
                    table.laser(n, False)
            view = pose_lines(off, frames, board, rig.lasers)
            if isinstance(view, str):
                rejected.append(f"{names[i]}: {view}")
                view = None
            views.append(view)
        call_progress(progress, "laser calibration: board poses", n_poses, n_poses)
    except BaseException:
        try:
            _all_off(table, switches)
        except DeviceError:
            pass                    # the error that stopped the calibration is the one to show
        raise
    _all_off(table, switches)
    camera = rig.camera
    T_cam, failed = pnp_board_poses(camera, board, views, names)
    lasers, cals, fit_rejected = fit_laser_planes(rig.lasers, camera, board, views, T_cam, names,
                                                  min_points=min_points)
    return LaserCalibration(rig=replace(rig, lasers=tuple(lasers)), lasers=tuple(cals), errors=None,
                            camera_errors=None, truth=None, rejected=tuple(rejected + failed + fit_rejected),
                            camera_rms=math.nan, seconds=time.perf_counter() - t0)
