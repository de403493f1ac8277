"""``rangekit rig init``, ``rangekit calibrate`` and ``rangekit devices``: the rig file and the hardware."""

from __future__ import annotations

import argparse
import errno
import sys
import time
from pathlib import Path

from rangekit.cli._common import (check_beside, check_output, console, finite_float, float_in, int_in, note, positive_float,
                                  result, say, seed, size)
from rangekit.drivers.discovery import MAX_SEARCH_S
from rangekit.errors import UsageError
from rangekit.formats.sessions.files import RIG_FILE


def cmd_rig_init(args: argparse.Namespace) -> int:
    """rangekit rig init [--sim] [--camera TYPE] > rig.json: a template rig file, or the simulator's true rig"""
    if args.sim:
        from rangekit.sim import default_rig

        data = default_rig().to_dict()
    else:
        from rangekit.rig.rig_file import template_rig

        data = template_rig(camera=args.camera)
    _print_rig(data, f"rangekit rig init > {RIG_FILE}")
    return 0


def _print_rig(data: dict, example: str) -> None:
    """A rig file on standard output, each matrix on one line (:func:`rangekit.formats.rig_files.json_text.rig_json_text`)."""
    from rangekit.formats.rig_files.json_text import rig_json_text

    if sys.stdout is None:
        raise OSError(errno.EBADF, f"standard output is closed; redirect it to a file: {example}", "<stdout>")
    sys.stdout.write(rig_json_text(data))


def cmd_rig_import(args: argparse.Namespace) -> int:
    """rangekit rig import FILE [--out RIG.json]: a rig file from an OpenCV stereo calibration (YAML/XML), a
    structured-light tool's calibration, a depthai EEPROM calibration JSON or a Horus calibration.json"""
    from rangekit.formats.rig_files.importers import import_rig
    from rangekit.formats.rig_files.json_text import rig_json_text
    from rangekit.io import atomic_write_text
    from rangekit.rig.rig_file import RIG_SUFFIXES

    if args.out is not None:
        check_output(args.out, force=args.force, suffixes=RIG_SUFFIXES, what="rig",
                     inputs=list(args.file) + list(args.capture or []))
    options = dict(size=args.size, projector_size=args.projector_size, unit=args.unit,
                   keep_projector_distortion=args.keep_projector_distortion)
    if len(args.file) > 1 or args.capture:
        if not args.capture:
            raise UsageError(f"{len(args.file)} calibration files: give --capture DIR to rank them by (the one that "
                             "fits the capture best is written)")
        path = _best_fitting(args, options)
        args.file = [path]
    data = import_rig(args.file[0], **options, report=note)
    if args.out is None:
        _print_rig(data, f"rangekit rig import {args.file[0]} > {RIG_FILE}")
        return 0
    atomic_write_text(args.out, rig_json_text(data))
    kinds = [f"{len(data['cameras'])} camera(s)"] + (["a projector"] if data["projector"] else []) + (
        [f"{len(data['lasers'])} laser(s)"] if data.get("lasers") else []) + (
        ["the turntable"] if data["T_world_table"] is not None else ["no turntable (rangekit calibrate measures it)"])
    result(f"wrote {args.out}: {', '.join(kinds)} from {args.file[0]}")
    return 0


def _best_fitting(args: argparse.Namespace, options: dict) -> str:
    """The calibration file of ``args.file`` that fits ``args.capture`` best (the ranking said, one line a file)."""
    from rangekit.app.commands.reconstruct import reconstruct_checked, reconstruct_tool_capture
    from rangekit.formats.rig_files.importers import import_rig
    from rangekit.rig.rig_file import Rig

    rigs = []
    for path in args.file:
        rigs.append((str(path), Rig.from_dict(import_rig(path, **options, report=say), where=str(path))))
    if args.pattern is not None:
        checked = reconstruct_tool_capture(args.capture, args.pattern, rigs, projector_size=args.projector,
                                           refine=False, report=say)
    else:
        if len(args.capture) != 1:
            raise UsageError("--capture: one rangekit capture folder, or another tool's with --pattern PRESET")
        checked = reconstruct_checked(args.capture[0], rigs, refine=False)
    for line in checked.choice.lines() or [f"rig 1 of 1: {rigs[0][0]}: {checked.choice.check.describe()}"]:
        note(line)
    if checked.choice.check.checkable and not checked.choice.check.fits:
        note(f"the best of them, {checked.choice.name}, does NOT fit the capture either: "
             f"{checked.choice.check.describe()}")
    return checked.choice.name


def cmd_calibrate(args: argparse.Namespace) -> int:
    """rangekit calibrate --rig sim|RIG.json --out RIG.json [--lasers]: camera, projector, turntable and projector
    response (and with --lasers the line lasers' planes: on the simulator after the rest, on hardware alone with
    the rig file's calibrated camera); rangekit calibrate --captures DIR [DIR ...] --pattern PRESET --projector
    WxH --out RIG.json: camera and projector from board poses another tool recorded"""
    from rangekit.app.calibrate import calibrate
    from rangekit.boards import Board
    from rangekit.rig.rig_file import RIG_SUFFIXES

    t0 = time.perf_counter()
    _check_captures_options(args)
    inputs = list(args.captures or []) + ([args.rig] if args.rig != "sim" else [])
    check_output(args.out, force=args.force, suffixes=RIG_SUFFIXES, what="rig", inputs=inputs)
    check_beside(args.out, ("coverage.png",), force=args.force, inputs=inputs)
    _check_square(args.square_mm)
    board = Board(kind=args.board, cols=args.cols, rows=args.rows, square=args.square_mm / 1000.0)
    if args.captures and args.lasers:
        return _calibrate_laser_recordings(args, board, t0)
    if args.captures:
        from rangekit.app.calibrate_recorded import calibrate_recordings

        cal = calibrate_recordings(args.out, args.captures, pattern=args.pattern, projector_size=args.projector,
                                   board=board, lens=args.lens, corners=args.corners, force=args.force,
                                   progress=console(), report=say)
    else:
        cal = calibrate(args.out, rig=args.rig, board=board, n_poses=args.poses, seed=args.seed, force=args.force,
                        interactive=sys.stdin.isatty(), ask=input, progress=console(), lasers=args.lasers,
                        laser_poses=args.laser_poses, report=say, lens=args.lens)
    say("")
    if cal.result is not None:
        say("== calibration ==")
        for line in cal.result.summary_lines():
            say(line)
        say(f"coverage of the camera image: {Path(args.out).parent / 'coverage.png'}")
    if cal.truth is not None:
        say("deviation from the simulator's true rig (rangekit rig init --sim):")
        for line in cal.deviation:
            say("  " + line)
    if cal.lasers is not None:
        say("== laser planes ==")
        for line in cal.lasers.summary_lines():
            say(line)
    result(f"wrote {args.out} in {time.perf_counter() - t0:.1f} s")
    return 0


def _calibrate_laser_recordings(args: argparse.Namespace, board, t0: float) -> int:
    """``rangekit calibrate --lasers --captures DIR [DIR ...] --pattern laser:...``: a laser rig from recorded board
    sweeps on the turntable (docs/laser.md, "A webcam laser rig from recorded frames")."""
    from rangekit.app.laser.recorded_calibration import calibrate_laser_recordings

    cal = calibrate_laser_recordings(args.out, args.captures, layout=args.pattern or "laser:folders", board=board,
                                     step_deg=args.step_deg, lens=args.lens, force=args.force, report=say)
    say("")
    say("== laser rig ==")
    for line in cal.summary_lines():
        say(line)
    result(f"wrote {args.out} in {time.perf_counter() - t0:.1f} s")
    return 0


def _check_square(square_mm: float) -> None:
    """--square-mm against the one rule of a board's square (rangekit.rig.plausibility.BOARD_SQUARE): refused
    before any pose (a 1e9 mm square otherwise fails as "no pose found" or as poses nearly parallel)."""
    from rangekit.rig.plausibility import BOARD_SQUARE, check_length

    check_length(square_mm / 1000.0, BOARD_SQUARE, where="--square-mm", shown=f"{square_mm:g} mm",
                 what="square side", read_as="mm", units=("m", "cm"), source="the number",
                 fixes={"m": f"give millimetres, --square-mm {square_mm * 1000:g}",
                        "cm": f"give millimetres, --square-mm {square_mm * 10:g}"}, error=UsageError)


def _check_captures_options(args: argparse.Namespace) -> None:
    """--captures needs --pattern and --projector, and takes none of the options of a calibration that captures
    its own poses; those two are refused without it. UsageError naming the option."""
    from rangekit.errors import UsageError

    from rangekit.formats.layouts.laser import LASER_LAYOUTS

    if not args.captures:
        given = [name for name, value in (("--pattern", args.pattern), ("--projector", args.projector),
                                          ("--corners", args.corners != "quadratic"),
                                          ("--step-deg", args.step_deg is not None)) if value]
        if given:
            raise UsageError(f"{given[0]}: only with --captures DIR [DIR ...] (board poses another tool recorded)")
        return
    if args.lasers or (args.pattern or "") in LASER_LAYOUTS:
        _check_laser_captures_options(args, LASER_LAYOUTS)
        return
    if args.step_deg is not None:
        raise UsageError("--step-deg: only with --lasers --captures (recorded laser board sweeps)")
    needed = (("--pattern", args.pattern, "the folders' capture layout, e.g. slstudio:calibration"),
              ("--projector", args.projector, "the projector screen the tool drew its patterns on, WxH, e.g. "
                                              "1824x1140"))
    for name, value, what in needed:
        if value is None:
            raise UsageError(f"--captures: give {name} ({what})")
    defaults = (("--rig", args.rig, "sim"), ("--poses", args.poses, 20), ("--seed", args.seed, 0),
                ("--lasers", args.lasers, False), ("--laser-poses", args.laser_poses, 10))
    for name, value, default in defaults:
        if value != default:
            raise UsageError(f"{name}: not with --captures (the recorded folders are the board poses; the rig "
                             "file is written from them alone)")


def _check_laser_captures_options(args: argparse.Namespace, layouts) -> None:
    """--lasers --captures: the folders are laser recordings (--pattern a laser layout, default laser:folders); the
    options of a coded-light recording or of a calibration that captures its own poses are refused by name."""
    if not args.lasers:
        raise UsageError(f"--pattern {args.pattern}: a laser recording layout; calibrate from it with --lasers")
    if args.pattern is not None and args.pattern not in layouts:
        raise UsageError(f"--pattern {args.pattern}: with --lasers --captures, expected a laser recording layout "
                         f"({', '.join(layouts)})")
    refused = (("--projector", args.projector is not None), ("--corners", args.corners != "quadratic"),
               ("--rig", args.rig != "sim"), ("--poses", args.poses != 20), ("--seed", args.seed != 0),
               ("--laser-poses", args.laser_poses != 10))
    for name, given in refused:
        if given:
            raise UsageError(f"{name}: not with --lasers --captures (the recorded board sweeps are the poses; the rig "
                             "file is written from them alone)")


def cmd_devices(args: argparse.Namespace) -> int:
    """rangekit devices [--timeout 1.0]: list serial ports and the cameras of every camera driver"""
    from rangekit.drivers.cameras import CAMERA_DRIVERS, camera_driver
    from rangekit.errors import DeviceError
    from rangekit.drivers.discovery import list_serial_ports

    ports = list_serial_ports()
    result("serial ports:" if ports else "serial ports: none found")
    for p in ports:
        result(f"  {p['device']}  {p['description']}  USB {p['vid_pid'] or '-'}  serial {p['serial_number'] or '-'}")
    for kind, driver in CAMERA_DRIVERS.items():
        t0 = time.monotonic()
        try:
            cams = camera_driver(kind).list_cameras(timeout_s=args.timeout)
        except DeviceError as exc:     # its package missing (MissingPackage), a bad producer path, ...
            result(f"{kind} cameras: not listed: {exc}")
            continue
        searched = f"(search limit {args.timeout:g} s; {time.monotonic() - t0:.2f} s with loading its package)"
        result(f"{kind} cameras: {searched}" if cams else f"{kind} cameras: none found {searched}")
        for c in cams:
            result(f"  {c.id}  {c.name}  {c.detail}".rstrip())
    return 0


def add_calibrate_parser(sub) -> None:
    from rangekit.calib.camera import CORNER_FITS, LENS_MODELS
    from rangekit.formats.layouts import LAYOUTS as CAPTURE_LAYOUTS
    from rangekit.formats.layouts.laser import LASER_LAYOUTS

    cal = sub.add_parser("calibrate", help="calibrate camera, projector, turntable axis and projector response",
                         description="Capture a board at several poses under coded light (the simulator moves it; "
                                     "on hardware you do, pose by pose), calibrate the camera and the projector "
                                     "(bundle adjusted together), the turntable axis and the projector's gamma, and "
                                     "write a rig file. Each pose is checked as it is captured (board found, corners, "
                                     "size in the image, tilt, reprojection error): a rejected pose says why and is "
                                     "skipped, or on hardware in a terminal you may retake it; coverage.png beside --out "
                                     "shows the parts of the image covered so far. On the simulator it also prints "
                                     "each parameter's deviation from the true rig. With --captures the board "
                                     "poses are folders another tool recorded under its coded light (a capture "
                                     "layout, --pattern): the camera and the projector are calibrated from them "
                                     "(Moreno and Taubin's local homographies, then the same bundle adjustment "
                                     "and checks; docs/real-captures.md).")
    cal.add_argument("--rig", default="sim", help="'sim' (default) or a rig file naming the devices (its geometry "
                                                   "is replaced)")
    cal.add_argument("--out", required=True, help="rig file to write")
    cal.add_argument("--force", action="store_true", help="overwrite --out and coverage.png beside it if they exist")
    cal.add_argument("--poses", type=int_in(3, 200), default=20, help="board poses (default 20)")
    cal.add_argument("--board", default="checkerboard", choices=("checkerboard", "charuco"), help="board type")
    cal.add_argument("--cols", type=int_in(3, 60), default=10, help="squares along the board's width (default 10)")
    cal.add_argument("--rows", type=int_in(3, 60), default=7, help="squares along its height (default 7)")
    cal.add_argument("--square-mm", type=positive_float, default=20.0, help="square side in millimetres (default 20)")
    cal.add_argument("--seed", type=seed, default=0, help="simulator: noise and pose seed")
    cal.add_argument("--lasers", action="store_true",
                     help="calibrate the line lasers' planes from board poses crossed by the lines, written to "
                          "the rig file's 'lasers'; simulator: after the camera (the Ciclop rig's two lasers), with "
                          "each plane's error against the truth; hardware rig file: the lasers alone, with its "
                          "calibrated camera (you place the board; docs/laser.md); prints every rejected pose")
    cal.add_argument("--laser-poses", type=int_in(2, 200), default=10,
                     help="with --lasers: board poses for the laser planes (default 10)")
    cal.add_argument("--captures", nargs="+", metavar="DIR",
                     help="calibrate from board poses another tool recorded, one folder per pose in the capture "
                          "layout --pattern (docs/real-captures.md); needs --projector. With --lasers: a laser rig "
                          "(camera, turntable axis, laser planes) from recorded board sweeps on the turntable, one "
                          "folder per sweep in a laser layout (docs/laser.md)")
    cal.add_argument("--pattern", choices=sorted(CAPTURE_LAYOUTS) + list(LASER_LAYOUTS), default=None,
                     help="with --captures: the folders' capture layout; it must code columns and rows (e.g. "
                          "slstudio:calibration); with --lasers --captures a laser recording layout (default "
                          "laser:folders: off/, laser0/, laser1/ subfolders; docs/laser.md)")
    cal.add_argument("--step-deg", type=finite_float, default=None,
                     help="with --lasers --captures: the turntable's step between the recorded frames, degrees (a "
                          "recording with a steps.csv gives each step's angle instead)")
    cal.add_argument("--projector", type=size, default=None,
                     help="with --captures: the projector screen the patterns were drawn on, WxH (e.g. 1824x1140)")
    cal.add_argument("--corners", choices=CORNER_FITS, default=CORNER_FITS[0],
                     help="with --captures: each corner's projector coordinates from the decoded maps around it: "
                          "quadratic (rangekit's robust local regression, as calibrate on devices; default) or "
                          "homography (Moreno and Taubin's local homography, patented: US 10008007)")
    cal.add_argument("--lens", choices=tuple(LENS_MODELS), default="k1k2p",
                     help="what each device's lens model fits: " + "; ".join(
                         f"{m.name}: {m.description}" for m in LENS_MODELS.values()) + " (default k1k2p)")
    cal.set_defaults(func=cmd_calibrate)


def add_parsers(sub) -> None:
    from rangekit.formats.layouts import LAYOUTS as CAPTURE_LAYOUTS
    from rangekit.rig.checks import CAMERA_TEMPLATES

    rig = sub.add_parser("rig", help="rig files: write a template, import a calibration",
                         description="Rig files (docs/rig.md documents every field).")
    rig_sub = rig.add_subparsers(dest="rig_command", metavar="SUBCOMMAND")
    rig_sub.required = True
    init = rig_sub.add_parser("init", help=f"print a template rig file for real hardware (rangekit rig init > {RIG_FILE})",
                              description="Print a rig file to standard output: a template to edit for real "
                                          "hardware, or with --sim the simulator's default rig (its true "
                                          "parameters).")
    init.add_argument("--sim", action="store_true", help="print the simulator's default rig instead")
    init.add_argument("--camera", choices=CAMERA_TEMPLATES, default="depthai",
                      help="the camera driver whose section devices.camera holds (default depthai; docs/hardware.md)")
    init.set_defaults(func=cmd_rig_init)
    imp = rig_sub.add_parser("import", help="a rig file from an OpenCV stereo calibration, a structured-light "
                                            "tool's calibration, a depthai EEPROM JSON or a Horus calibration.json",
                             description="Convert a calibration you already have into a rig file: an OpenCV "
                                         "stereo calibration written by cv2.FileStorage (YAML/XML; the camera, "
                                         "then the projector as the second device: K1/D1/K2/D2/R/T or "
                                         "cameraMatrix1/distCoeffs1/..., docs/rig.md lists the keys), a "
                                         "structured-light tool's file recognised by its keys (SLStudio's "
                                         "calibration.xml, kamino410 procam-calibration's calibration_result.xml, "
                                         "Moreno-Taubin scan3d-capture's calibration.yml, OpenCV's "
                                         "structured_light sample's two-camera calibration; "
                                         "docs/real-captures.md), a depthai EEPROM calibration "
                                         "(CalibrationHandler.eepromToJson()) or a Horus calibration.json "
                                         "(Ciclop: camera, laser planes, platform). Printed, or written to --out.")
    imp.add_argument("file", metavar="FILE", nargs="+",
                     help="the calibration file (.yaml, .yml, .xml or .json); several: each imported and checked "
                          "against --capture, the one that fits it best written, the ranking printed")
    imp.add_argument("--capture", nargs="+", metavar="DIR",
                     help="with several files: the capture to rank them by (a rangekit capture folder, or another "
                          "tool's with --pattern, as 'rangekit reconstruct' reads it)")
    imp.add_argument("--pattern", choices=sorted(CAPTURE_LAYOUTS), default=None,
                     help="with --capture: another tool's capture layout (docs/real-captures.md)")
    imp.add_argument("--projector", type=size, default=None,
                     help="with --capture --pattern and two-camera calibrations: the projector's size WxH")
    imp.add_argument("--out", help="rig file to write (default: print it)")
    imp.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    imp.add_argument("--size", type=size, help="camera image size WxH where the file has none (Horus: read from camera_width, camera_height)")
    imp.add_argument("--projector-size", type=size, help="projector size WxH where the file has none (kamino410 "
                                                           "procam-calibration, Moreno-Taubin: always)")
    imp.add_argument("--unit", choices=("m", "cm", "mm"), default=None,
                     help="unit of the file's translation: an OpenCV file's T (default m) or a structured-light "
                          "tool's (default the tool's, mm; it prints the unit it read); depthai's cm and Horus's "
                          "mm are known")
    imp.add_argument("--keep-projector-distortion", action="store_true",
                     help="keep the projector's lens distortion of a tool whose own triangulation leaves it out "
                          "(SLStudio: by default the import follows the tool, so its clouds and rangekit's agree)")
    imp.set_defaults(func=cmd_rig_import)

    dev = sub.add_parser("devices", help="list serial ports and cameras",
                         description="List serial ports (device, USB VID:PID, serial number) and the cameras of "
                                     "every camera driver (docs/hardware.md), each with the id its rig file "
                                     "section takes.")
    dev.add_argument("--timeout", type=float_in(0.0, MAX_SEARCH_S), default=1.0,
                     help=f"seconds to search for cameras of each driver, 0..{MAX_SEARCH_S:g} (default 1)")
    dev.set_defaults(func=cmd_devices)
