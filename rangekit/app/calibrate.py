"""Calibrating a rig, on the simulator or on hardware: the work behind ``rangekit calibrate``.

On hardware the person moves the board: :func:`calibrate` asks them (``ask(prompt)``, e.g. ``input``) to
place it for each pose and on the turntable. On the simulator the board is moved by the code and the
result is compared with the simulator's true rig.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from rangekit.app.board_placer import AskedPlacer, SimulatedPlacer
from rangekit.boards import Board
from rangekit.errors import ConfigError, UsageError
from rangekit.io import write_png
from rangekit.rig.rig_file import Rig, load_rig, save_rig
from rangekit.rig.checks import validate_rig_for_hardware

__all__ = ["Calibration", "calibrate"]

@dataclass(frozen=True, eq=False)
class Calibration:
    result: object             # rangekit.calib.procedure.CalibrationResult (its rig, summary_lines())
    truth: Rig | None          # the simulator's true rig; None on hardware
    deviation: list[str]       # simulator: each parameter's deviation from the truth, one line each
    lasers: object = None      # rangekit.app.laser.calibration.LaserCalibration with ``lasers``; else None
    # ``result`` is None after ``--lasers`` on hardware (the laser planes alone are calibrated there)


def calibrate(out: str | Path, *, rig: str = "sim", board: Board, n_poses: int = 20, seed: int = 0,
              force: bool = False, interactive: bool = False, ask: Callable[[str], object] = input,
              progress: Callable | None = None, lasers: bool = False, laser_poses: int = 10,
              report: Callable[[str], object] | None = None, lens: str = "k1k2p") -> Calibration:
    """Calibrate the camera, projector, turntable axis and projector response; write the rig file ``out``.

    ``rig`` is "sim" or a rig file naming the devices (its geometry is replaced). On hardware,
    ``interactive`` must be true (someone moves the board; ``ask`` prompts them). With ``lasers`` (the
    simulator) the simulated Ciclop rig's laser planes are calibrated too, from ``laser_poses`` board
    poses with the calibrated camera (:func:`rangekit.app.laser.calibration.calibrate_lasers`), and written
    into the rig file's ``lasers``; on hardware ``lasers`` calibrates the laser planes alone, with the rig
    file's calibrated camera (the person places the board, :mod:`rangekit.app.laser.calibration_hw`), and
    writes the rig file with the fitted planes, everything else unchanged.

    ``lens`` names what each device's lens model fits (:data:`rangekit.calib.camera.LENS_MODELS`). Each board
    pose is checked as it is captured (:mod:`rangekit.calib.pose_feedback`): ``report`` gets
    one line per capture (kept, or rejected and why), and ``coverage.png`` beside ``out`` shows which parts
    of the camera image the kept poses' corners have covered (rewritten atomically after each pose). A
    rejected pose is skipped and counted, or on hardware with ``interactive`` the person is asked whether
    to retake it.

    Raises
    ------
    UsageError
        ``out`` exists (without ``force``), fewer than 3 poses, fewer than 2 laser poses.
    ConfigError
        Hardware without a terminal, a bad rig file; with ``lasers`` on hardware: no ``lasers``, an
        uncalibrated camera, no camera or turntable board in ``devices`` (before any device is opened).
    CalibrationError
        A laser plane cannot be calibrated (named).
    """
    from rangekit.calib.procedure import CalibrationSettings, compare_rigs, comparison_lines

    out = Path(out)
    if out.exists() and not force:
        raise UsageError(f"--out {out}: exists; choose another file or pass --force to overwrite it")
    if n_poses < 3:
        raise UsageError(f"--poses must be at least 3 (Zhang's method), found {n_poses}; 15-25 is typical")
    settings = CalibrationSettings(board=board, n_poses=n_poses, lens=lens)
    hardware = rig != "sim"
    if lasers and laser_poses < 2:
        raise UsageError(f"--laser-poses must be at least 2 (two board lines fix a plane), found {laser_poses}; "
                         "10 is typical")
    if lasers and hardware:
        return _calibrate_hardware_lasers(out, rig, board=board, n_poses=laser_poses, interactive=interactive,
                                          ask=ask, progress=progress)
    if hardware:
        template, devices = _open_hardware(rig, interactive)
        truth, placer = None, AskedPlacer(board, ask)
    else:
        template, devices, placer = _open_simulator(board, n_poses, seed)
        truth = template
    on_pose = _pose_reporter(out.parent / "coverage.png", report, ask if hardware and interactive else None)
    res = _watched_calibration(devices, settings, placer, template, progress, on_pose, out.parent / "coverage.png",
                               close=hardware)
    laser_cal = None
    out_rig = res.rig
    if lasers:
        from dataclasses import replace

        from rangekit.app.laser.calibration import calibrate_lasers
        from rangekit.sim.laser.rig import laser_rig

        laser_cal = calibrate_lasers(laser_rig(truth), n_poses=laser_poses, seed=seed, board=board,
                                     camera=res.rig.camera, progress=progress)
        out_rig = replace(res.rig, lasers=laser_cal.rig.lasers)
    save_rig(out_rig, out)
    deviation = comparison_lines(compare_rigs(res.rig, truth)) if truth is not None else []
    return Calibration(res, truth, deviation, laser_cal)


def _open_hardware(rig: str, interactive: bool) -> tuple[Rig, object]:
    """The rig file ``rig`` (the template) and its opened devices; ConfigError for a rig without a projector
    display, or when no one is there to move the board (not ``interactive``), before any device is opened."""
    from rangekit.drivers import open_rig_devices

    template = load_rig(rig)
    validate_rig_for_hardware(template, where=rig)
    if template.projector is None or "display" not in ((template.devices or {}).get("projector") or {}):
        raise ConfigError(f"{rig}: devices.projector.display: expected a projector display (the camera and "
                          "turntable are calibrated with its coded light), found none; a rig without a "
                          "projector (Ciclop, FabScan) takes its camera from the depthai factory calibration "
                          "(docs/rig.md) and can then calibrate its lasers with --lasers (docs/laser.md)")
    if not interactive:
        raise ConfigError("calibrating real hardware is interactive (you move the board between captures); "
                          "run 'rangekit calibrate' in a terminal")
    return template, open_rig_devices(template, where=rig)


def _open_simulator(board: Board, n_poses: int, seed: int) -> tuple[Rig, object, SimulatedPlacer]:
    """The simulator's true rig, its devices showing the board at the first of ``n_poses`` poses (seeded), and the
    placer that moves it."""
    from rangekit.sim.writers.calibration import board_poses, board_scene
    from rangekit.sim.devices.sim_rig import SimRig, default_rig

    truth = default_rig()
    poses = board_poses(truth, board, n_poses, seed=seed)
    devices = SimRig(board_scene(board, poses[0]), truth, seed=seed)
    return truth, devices, SimulatedPlacer(devices, board, poses, truth)


def _pose_reporter(coverage_png: Path, report: Callable[[str], object] | None,
                   ask: Callable[[str], object] | None) -> Callable[[object, object], bool]:
    """``on_pose(check, coverage) -> retake`` for :func:`rangekit.calib.procedure.calibrate_rig`: the coverage
    picture written to ``coverage_png``, the verdict's line to ``report``; a rejected pose retaken unless the person
    answers no when ``ask`` is given (hardware, interactive), else skipped."""
    def on_pose(check, coverage) -> bool:
        write_png(coverage_png, coverage)
        if report is not None:
            report(check.line())
        if check.accepted or ask is None:
            return False
        answer = ask(f"pose {check.index + 1} rejected ({check.reason}); retake it? [Y/n] ")
        return not str(answer).strip().lower().startswith("n")
    return on_pose


def _watched_calibration(devices, settings, placer, template: Rig, progress: Callable | None, on_pose,
                         coverage_png: Path, *, close: bool):
    """:func:`rangekit.calib.procedure.calibrate_rig` on ``devices`` moved by ``placer``; a failed run takes the
    ``coverage_png`` it wrote with it (a rerun is not refused for it); the devices closed after when ``close``."""
    from rangekit.calib.procedure import calibrate_rig

    coverage_was_there = coverage_png.exists()
    try:
        return calibrate_rig(devices, settings=settings, place_board=placer.place,
                             place_on_turntable=placer.on_turntable, template=template, progress=progress,
                             on_pose=on_pose)
    except BaseException:
        if not coverage_was_there:   # the live picture of a failed run goes with it: a rerun is not refused for it
            coverage_png.unlink(missing_ok=True)
        raise
    finally:
        if close:
            devices.close()


def _calibrate_hardware_lasers(out: Path, rig: str, *, board: Board, n_poses: int, interactive: bool,
                               ask: Callable[[str], object], progress: Callable | None) -> Calibration:
    """``rangekit calibrate --lasers --rig RIG.json``: the laser planes of a rig whose camera is calibrated
    (:func:`rangekit.app.laser.calibration_hw.calibrate_lasers_on_devices`); the rig file ``out`` is ``rig``
    with the fitted planes, everything else unchanged, written only when every plane was fitted."""
    from rangekit.app.laser.calibration_hw import calibrate_lasers_on_devices, check_laser_rig
    from rangekit.drivers import open_rig_devices

    template = load_rig(rig)
    validate_rig_for_hardware(template, where=rig)
    check_laser_rig(template, where=rig)
    if not interactive:
        raise ConfigError("calibrating the lasers on real hardware is interactive (you move the board between "
                          "captures); run 'rangekit calibrate --lasers' in a terminal")
    devices = open_rig_devices(template, where=rig, open_display=False)
    try:
        laser_cal = calibrate_lasers_on_devices(devices, template, n_poses=n_poses, ask=ask, board=board,
                                                progress=progress, where=rig)
    finally:
        devices.close()
    save_rig(laser_cal.rig, out)
    return Calibration(None, None, [], laser_cal)
