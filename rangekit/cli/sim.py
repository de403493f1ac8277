"""``rangekit sim render``: simulated captures with exact ground truth; ``rangekit sim objects``: the built-in
objects."""

from __future__ import annotations

import argparse
import time

import numpy as np

from rangekit.formats.output_sets import claim_folder
from rangekit.cli._common import (LazyChoices, check_output, console, finite_float, float_in, int_in, non_negative_float, positive_float,
                                  result, seed, size)
from rangekit.errors import UsageError
from rangekit.tof.plan import FREQUENCY_RANGE_HZ
from rangekit.formats.sessions.files import PATTERNS_FILE, RIG_FILE

#: The ToF panel scene's defaults: nearest and farthest panel (m), the pulsed sensor's timing jitter (ps RMS).
TOF_NEAR_M, TOF_FAR_M, TOF_JITTER_PS = 0.5, 15.0, 50.0
#: --frequencies-mhz: the frequencies a continuous-wave sensor may be given, MHz.
TOF_MHZ = (FREQUENCY_RANGE_HZ[0] / 1e6, FREQUENCY_RANGE_HZ[1] / 1e6)


def cmd_sim_render(args: argparse.Namespace) -> int:
    """rangekit sim render: the capture, written where no other command's set of files is (--force replaces one)."""
    check_output(args.out, folder=True)
    replace = claim_folder(args.out, "capture", force=args.force, inputs=[args.rig, args.object],
                           names=_WRITES[args.sensor])
    code = _sim_render(args)
    replace()
    return code


#: What each sensor writes into --out (rangekit.formats.output_sets: the capture set's members).
_WRITES = {
    "projector": ("[0-9][0-9][0-9].png", PATTERNS_FILE, RIG_FILE, "capture.json", "ground_truth.npz", "preview.png"),
    "laser": ("off.png", "laser*.png", RIG_FILE, "capture.json", "ground_truth.npz"),
    "laser-stereo": ("left", "right", RIG_FILE, "capture.json", "ground_truth.npz"),
    "laser-recording": ("off", "laser[0-9]", "[0-9][0-9][0-9][0-9][0-9].png", "steps.csv", "truth.json",
                        "true-rig.json"),
    "laser-board": ("sweep_[0-9]*",),
    "dots": ("image.png", "reference.png", RIG_FILE, "capture.json", "ground_truth.npz"),
    "stereo": ("left.png", "right.png", RIG_FILE, "capture.json", "ground_truth.npz", "preview.png"),
    "tof": ("samples", "tof.json", RIG_FILE, "ground_truth.npz", "preview.png"),
    "tof-pulsed": ("round_trip_s.npy", "tof.json", RIG_FILE, "ground_truth.npz", "preview.png"),
}


def _sim_render(args: argparse.Namespace) -> int:
    """rangekit sim render [--sensor projector|laser|laser-stereo|tof|tof-pulsed|stereo|dots] [--object NAME_OR_MESH]
    --out DIR"""
    from rangekit.app.commands.simulate import (render_dots_capture, render_laser_capture, render_laser_stereo_capture,
                                                render_projector_capture, render_stereo_capture, render_tof_capture)

    t0 = time.perf_counter()
    check_output(args.out, folder=True)
    _check_motion_options(args)
    _check_sensor_options(args)
    _check_recording_options(args)
    if args.sensor in LASER_SENSORS:
        given = [f for f, v in (("--patterns", args.patterns), ("--global-fraction", args.global_fraction),
                                ("--motion-mm", args.motion_mm)) if v is not None]
        if given:
            raise UsageError(f"{', '.join(given)}: only for --sensor projector; the {args.sensor} sensor draws line "
                             "lasers (docs/simulator.md)")
    elif args.mono:
        raise UsageError(f"--mono: only for --sensor laser or laser-stereo, found --sensor {args.sensor}")
    if args.sensor not in ("projector", *LASER_SENSORS):
        given = [f for f, v in (("--object", args.object), ("--object-unit", args.object_unit),
                                ("--patterns", args.patterns), ("--rig", args.rig), ("--motion-mm", args.motion_mm),
                                ("--global-fraction", args.global_fraction), ("--angle-deg", args.angle_deg),
                                ("--bits", args.bits))
                 if v is not None]
        if given:
            raise UsageError(f"{', '.join(given)}: only for --sensor projector, laser or laser-stereo; the "
                             f"{args.sensor} sensor renders its own scene (docs/simulator.md)")
    if args.sensor in ("laser-recording", "laser-board"):
        from rangekit.app.commands.simulate import render_laser_recording

        folders = render_laser_recording(args.out, board=args.sensor == "laser-board", obj=args.object or "lumpy",
                                         rig_file=args.rig, steps=args.laser_steps or 100,
                                         layout=args.layout or "laser:folders", seed=args.seed,
                                         noise=not args.no_noise, colour=not args.mono, progress=console())
        result(f"wrote {len(folders)} recording(s) ({', '.join(str(f) for f in folders)}) with their truth "
               f"(truth.json, true-rig.json) in {time.perf_counter() - t0:.1f} s")
        return 0
    if args.sensor == "laser":
        render_laser_capture(args.out, obj=args.object or "lumpy", rig_file=args.rig,
                             angle=np.radians(args.angle_deg or 0.0), bits=args.bits or 8, seed=args.seed,
                             noise=not args.no_noise, colour=not args.mono, object_unit=args.object_unit or "m",
                             progress=console())
        result(f"wrote {args.out} (off.png, laser<k>.png, {RIG_FILE}, ground_truth.npz) in {time.perf_counter() - t0:.1f} s")
        return 0
    if args.sensor == "laser-stereo":
        render_laser_stereo_capture(args.out, obj=args.object or "lumpy", rig_file=args.rig,
                                    angle=np.radians(args.angle_deg or 0.0), bits=args.bits or 8, seed=args.seed,
                                    noise=not args.no_noise, colour=not args.mono,
                                    object_unit=args.object_unit or "m", progress=console())
        result(f"wrote {args.out} (left/ and right/ with off.png and laser<k>.png, {RIG_FILE}, capture.json, "
               f"ground_truth.npz) in {time.perf_counter() - t0:.1f} s")
        return 0
    if args.sensor == "dots":
        render_dots_capture(args.out, size=args.size or (640, 400), seed=args.seed, progress=console())
        result(f"wrote {args.out} (image.png, reference.png, {RIG_FILE}, capture.json, ground_truth.npz) in "
               f"{time.perf_counter() - t0:.1f} s")
        return 0
    if args.sensor == "stereo":
        render_stereo_capture(args.out, size=args.size or (640, 400), dots=not args.no_dots, seed=args.seed,
                              progress=console())
        result(f"wrote {args.out} (left.png, right.png, {RIG_FILE}, ground_truth.npz) in {time.perf_counter() - t0:.1f} s")
        return 0
    if args.sensor in ("tof", "tof-pulsed"):
        near = TOF_NEAR_M if args.near is None else args.near
        far = TOF_FAR_M if args.far is None else args.far
        if not near < far:
            raise UsageError(f"--near {near:g}, --far {far:g}: expected the nearest panel nearer than the "
                             "farthest (metres)")
        render_tof_capture(args.out, pulsed=args.sensor == "tof-pulsed", near=near, far=far,
                           size=args.size or (320, 240), plan=args.plan or "kinect",
                           frequencies=[f * 1e6 for f in args.frequencies_mhz] if args.frequencies_mhz else None,
                           steps=args.steps, multipath=args.multipath,
                           jitter=(TOF_JITTER_PS if args.jitter_ps is None else args.jitter_ps) * 1e-12,
                           noise=not args.no_noise, seed=args.seed, progress=console())
        result(f"wrote {args.out} (tof.json, {RIG_FILE}, ground_truth.npz, preview.png) in {time.perf_counter() - t0:.1f} s")
        return 0
    render_projector_capture(args.out, obj=args.object or "lumpy", patterns=args.patterns or "graycode",
                             rig_file=args.rig, angle=np.radians(args.angle_deg or 0.0), bits=args.bits or 8, seed=args.seed,
                             noise=not args.no_noise, global_fraction=args.global_fraction,
                             object_unit=args.object_unit or "m", progress=console(),
                             motion=None if not args.motion_mm else (args.motion or "slip", args.motion_mm * 1e-3),
                             readout_frames=args.readout_frames or 0.0)
    result(f"done in {time.perf_counter() - t0:.1f} s")
    return 0


#: The sensors that draw line lasers.
LASER_SENSORS = ("laser", "laser-stereo", "laser-recording", "laser-board")


def _check_recording_options(args: argparse.Namespace) -> None:
    """--laser-steps and --layout only for the laser recordings; --angle-deg and --bits not for them."""
    recording = args.sensor in ("laser-recording", "laser-board")
    given = [f for f, v in (("--laser-steps", args.laser_steps), ("--layout", args.layout)) if v is not None]
    if given and not recording:
        raise UsageError(f"{given[0]}: only for --sensor laser-recording or laser-board, found --sensor {args.sensor}")
    if args.laser_steps is not None and args.sensor == "laser-board":
        raise UsageError("--laser-steps: only for --sensor laser-recording (the board's sweeps are the simulator's)")
    if recording:
        given = [f for f, v in (("--angle-deg", args.angle_deg), ("--bits", args.bits),
                                ("--object-unit", args.object_unit)) if v is not None]
        if args.sensor == "laser-board" and args.object is not None:
            given.append("--object")
        if given:
            raise UsageError(f"{', '.join(given)}: not for --sensor {args.sensor} (a recording turns the table itself, "
                             "8-bit frames)")


def _check_sensor_options(args: argparse.Namespace) -> None:
    """The options of one kind of sensor refused with another (they were ignored), and --frequencies-mhz checked in
    the user's MHz (UsageError naming the option)."""
    tof = (("--plan", args.plan), ("--steps", args.steps), ("--frequencies-mhz", args.frequencies_mhz),
           ("--multipath", args.multipath))
    given = [f for f, v in tof if v is not None]
    if args.sensor == "tof-pulsed" and given:
        raise UsageError(f"{', '.join(given)}: only for --sensor tof (continuous wave); the pulsed sensor measures "
                         "round trips (--jitter-ps)")
    if args.sensor not in ("tof", "tof-pulsed") and given:
        raise UsageError(f"{', '.join(given)}: only for --sensor tof, found --sensor {args.sensor}")
    if args.jitter_ps is not None and args.sensor != "tof-pulsed":
        raise UsageError(f"--jitter-ps: only for --sensor tof-pulsed, found --sensor {args.sensor}")
    panels = [f for f, v in (("--near", args.near), ("--far", args.far)) if v is not None]
    if panels and args.sensor not in ("tof", "tof-pulsed"):
        raise UsageError(f"{', '.join(panels)}: only for --sensor tof or tof-pulsed (its panels); the {args.sensor} "
                         "sensor renders --object")
    if args.plan is not None and args.frequencies_mhz:
        raise UsageError(f"--plan {args.plan} with --frequencies-mhz: give one of them (--frequencies-mhz replaces "
                         "the plan)")
    if args.size is not None and args.sensor in ("projector", *LASER_SENSORS):
        raise UsageError(f"--size: only for --sensor tof, tof-pulsed, stereo or dots; the {args.sensor} sensor's "
                         "camera is the rig file's (--rig)")
    if args.no_noise and args.sensor in ("stereo", "dots"):
        raise UsageError(f"--no-noise: not for --sensor {args.sensor}; its images always carry shot and read noise "
                         "(--seed sets it)")
    if args.no_dots and args.sensor != "stereo":
        raise UsageError(f"--no-dots: only for --sensor stereo, found --sensor {args.sensor}")
    if args.frequencies_mhz:
        from rangekit.tof.plan import MAX_FREQUENCIES

        mhz = args.frequencies_mhz
        twice = sorted({f"{f:g}" for f in mhz if mhz.count(f) > 1})
        if twice or len(mhz) > MAX_FREQUENCIES:
            raise UsageError(f"--frequencies-mhz {' '.join(f'{f:g}' for f in mhz[:8])}{' ...' if len(mhz) > 8 else ''}: expected at most "
                             f"{MAX_FREQUENCIES} frequencies, distinct, in MHz" + (
                                 f", found {', '.join(twice)} more than once" if twice else f", found {len(mhz)}"))


def _check_motion_options(args: argparse.Namespace) -> None:
    """--motion and --readout-frames only with --motion-mm; --motion-mm within what the simulator moves (UsageError
    in the user's millimetres, before any rendering)."""
    from rangekit.sim.devices.motion import MAX_AMPLITUDE_M

    if not args.motion_mm:
        given = [f"{f} {v:g}" if isinstance(v, float) else f"{f} {v}"
                 for f, v in (("--readout-frames", args.readout_frames), ("--motion", args.motion)) if v is not None]
        if given:
            raise UsageError(f"{', '.join(given)}: only with --motion-mm MM (the object moving during the sequence); "
                             f"found {'--motion-mm 0' if args.motion_mm == 0 else 'no --motion-mm'}")
    elif args.motion_mm > MAX_AMPLITUDE_M * 1e3:
        raise UsageError(f"--motion-mm {args.motion_mm:g}: expected at most {MAX_AMPLITUDE_M * 1e3:g} mm (a slip or "
                         "a vibration of the object on the table, not a move out of the view)")


def cmd_sim_objects(args: argparse.Namespace) -> int:
    """rangekit sim objects: each built-in object with its size, triangle count and what makes it hard."""
    from rangekit.app.commands.sim_objects import format_objects, list_objects

    for line in format_objects(list_objects()):
        result(line)
    return 0


def add_parsers(sub) -> None:
    from rangekit.coded.patterns import PATTERN_METHODS
    from rangekit.rig.plausibility import OBJECT_UNITS

    sim = sub.add_parser("sim", help="simulated rig: render captures with exact ground truth",
                         description="Simulated projector-camera-turntable rig.")
    sim_sub = sim.add_subparsers(dest="sim_command", metavar="SUBCOMMAND")
    sim_sub.required = True
    render = sim_sub.add_parser(
        "render", help="render a pattern sequence on a simulated object and write captures + ground truth",
        description="Render the captures a real rig would take of an object, plus ground_truth.npz "
                    "(depth, xyz, normals, proj_col, proj_row, valid), the rig file and a preview PNG.")
    render.add_argument("--sensor", default="projector",
                        choices=("projector", "laser", "laser-stereo", "laser-recording", "laser-board", "tof",
                                 "tof-pulsed", "stereo", "dots"),
                        help="projector-camera rig (default), laser-line turntable scanner (Ciclop-like: off.png "
                             "and one image per laser), the same lasers seen by two cameras (laser-sheet stereo: "
                             "left/ and right/), a laser rig's recording of a turntable scan or of calibration "
                             "board sweeps in a laser layout with its truth (laser-recording, laser-board), "
                             "continuous-wave or pulsed time of flight, the "
                             "active-stereo pair, or one camera with a random-dot projector and its reference "
                             "image (Kinect v1 style)")
    render.add_argument("--object", default=None,
                        help="built-in object (plane, sphere, box, cylinder, torus, board, lumpy, and the zoo: "
                             "bunny, thin, bowl, shiny, dark, steps; 'rangekit sim objects' lists them) or a "
                             "mesh file trimesh can read (metres, or see --object-unit); default: lumpy")
    render.add_argument("--object-unit", default=None, choices=OBJECT_UNITS,
                        help="unit of the --object mesh file's coordinates (default m); a mesh whose size is "
                             "implausible in it (bounding-box diagonal above 5 m or below 1 mm) is refused")
    render.add_argument("--patterns", default=None, choices=PATTERN_METHODS,
                        help="pattern set to project; default: graycode (44 frames on the default rig)")
    render.add_argument("--out", required=True, help="output folder (created if missing)")
    render.add_argument("--force", action="store_true", help="write over files in --out this run did not make: another command's set (a session, a capture, results), files of yours, an input")
    render.add_argument("--rig", help="rig file to simulate (default: the built-in simulated rig; --sensor laser: "
                                      "it plus two red line lasers; a laser rig file must list 'lasers'; "
                                      "--sensor laser-stereo: also a second camera beside the first)")
    render.add_argument("--angle-deg", type=finite_float, default=None,
                        help="turntable angle in degrees (default 0; projector and laser sensors)")
    render.add_argument("--bits", type=int, default=None, choices=(8, 10, 12, 16),
                        help="camera bit depth (default 8; projector and laser sensors)")
    render.add_argument("--seed", type=seed, default=0, help="noise seed (default 0)")
    render.add_argument("--no-noise", action="store_true", help="disable shot and read noise")
    render.add_argument("--laser-steps", type=int_in(2, 3600), default=None, metavar="N",
                        help="--sensor laser-recording: turntable steps over a full turn (default 100)")
    render.add_argument("--layout", default=None, choices=LazyChoices("rangekit.formats.layouts.laser", "LASER_LAYOUTS"),
                        metavar="LAYOUT", help="--sensor laser-recording, laser-board: the recording's laser layout "
                                               "(default laser:folders; docs/laser.md)")
    render.add_argument("--mono", action="store_true",
                        help="--sensor laser, laser-stereo: a monochrome camera (default: RGB, the laser mostly in R)")
    render.add_argument("--global-fraction", type=float_in(0.0, 1.0), default=None,
                        help="interreflection term, fraction of the mean projected light, 0 to 1 (default 0)")
    render.add_argument("--motion-mm", type=non_negative_float, default=None, metavar="MM",
                        help="--sensor projector: the object moves MM millimetres along the world x axis during the "
                             "sequence (a slip halfway through it, or see --motion); the truth is where it started")
    render.add_argument("--motion", default=None, choices=LazyChoices("rangekit.sim.devices.motion", "MOTION_KINDS"),
                        metavar="{slip,vibration,breathing}",
                        help="how it moves with --motion-mm: slip (once, halfway), vibration or breathing (a period "
                             "of 8 frames); default slip")
    render.add_argument("--readout-frames", type=float_in(0.0, 1.0), default=None, metavar="FRAMES",
                        help="with --motion-mm: a rolling shutter whose last row is exposed FRAMES frames (0 to 1) "
                             "after its first (default 0: a global shutter)")
    tof = render.add_argument_group("time of flight (--sensor tof, tof-pulsed)")
    tof.add_argument("--plan", default=None, choices=("kinect", "luxonis"),
                     help="frequency plan: kinect = 16/80/120 MHz x 3 steps (18.7 m), luxonis = 80/100 MHz x 4 "
                          "steps (7.5 m); default kinect")
    tof.add_argument("--frequencies-mhz", type=float_in(TOF_MHZ[0], TOF_MHZ[1]), nargs="+",
                     help=f"custom frequencies in MHz, {TOF_MHZ[0]:g} to {TOF_MHZ[1]:g} (instead of --plan)")
    tof.add_argument("--steps", type=int_in(3, 64), help="phase steps per frequency (default: the plan's, or 4)")
    tof.add_argument("--near", type=positive_float, default=None, help=f"nearest panel, metres (default {TOF_NEAR_M:g})")
    tof.add_argument("--far", type=positive_float, default=None, help=f"farthest panel, metres (default {TOF_FAR_M:g})")
    tof.add_argument("--multipath", type=non_negative_float, nargs=2, metavar=("STRENGTH", "EXTRA_M"),
                     help="add a second return of STRENGTH x the direct light, EXTRA_M metres longer round trip")
    tof.add_argument("--jitter-ps", type=non_negative_float, default=None,
                     help=f"tof-pulsed: timing jitter, ps RMS (default {TOF_JITTER_PS:g})")
    sz = render.add_argument_group("time of flight and stereo")
    sz.add_argument("--size", type=size, default=None,
                    help="sensor size WIDTHxHEIGHT (default: tof 320x240, stereo and dots 640x400)")
    sz.add_argument("--no-dots", action="store_true", help="stereo: switch the dot projector off")
    render.set_defaults(func=cmd_sim_render)
    objects = sim_sub.add_parser(
        "objects", help="list the built-in objects: size, triangles, what makes each hard to scan",
        description="The simulator's built-in objects (for --object of 'rangekit sim render' and 'rangekit scan'), "
                    "each with its bounding box in mm, its triangle count and what makes it hard to scan.")
    objects.set_defaults(func=cmd_sim_objects)
