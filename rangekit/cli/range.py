"""``rangekit tof`` and ``rangekit stereo``: depth from time of flight and from an active stereo pair."""

from __future__ import annotations

import argparse
import math
import time

from rangekit.cli._common import check_output, fraction, int_in, non_negative_float, positive_float, result, say, size
from rangekit.errors import UsageError
from rangekit.formats.output_sets import claim_folder
from rangekit.formats.sessions.files import CLOUD_FILE, RIG_FILE

#: What ``tof`` and ``stereo`` write into --out (``stereo --device`` also the pair, its rig, the device's depth).
_DEPTH_FILES = ("depth.npy", "depth.png", "range.npy", "confidence.npy", "confidence.png", CLOUD_FILE)


def cmd_tof(args: argparse.Namespace) -> int:
    """rangekit tof RAW_DIR --out OUT: range, depth, confidence and a cloud from raw ToF samples."""
    from rangekit.app.commands.ranges import tof_depth_files

    t0 = time.perf_counter()
    check_output(args.out, folder=True)
    replace = claim_folder(args.out, "depth", force=args.force, inputs=[args.raw_dir], names=_DEPTH_FILES)
    run = tof_depth_files(args.raw_dir, args.out, min_snr=args.min_snr,
                          flying_angle=None if args.keep_flying else math.radians(args.flying_angle_deg),
                          max_range=args.max_range, min_fill=None if args.keep_flying else 0.5, progress=say)
    replace()
    result(f"wrote {args.out}/{', '.join(run.names)} ({run.n_points:,} points) in {time.perf_counter() - t0:.1f} s")
    return 0


def cmd_stereo(args: argparse.Namespace) -> int:
    """rangekit stereo LEFT RIGHT --rig RIG.json --out OUT: depth of the left camera from a stereo pair;
    rangekit stereo --device [--dots 0..1] [--on-device] --out OUT: from a pair captured on an attached OAK-D."""
    from rangekit.app.commands.ranges import stereo_depth_files

    if args.device:
        given = [n for n, v in (("LEFT", args.left), ("RIGHT", args.right), ("--rig", args.rig)) if v is not None]
        if given:
            raise UsageError(f"--device captures the pair and reads the device's calibration; drop "
                             f"{', '.join(given)} (found {' '.join(str(v) for v in (args.left, args.right, args.rig) if v)})")
        return _stereo_device(args)
    device_only = [n for n, v in (("--dots", args.dots), ("--flood", args.flood), ("--device-id", args.device_id),
                                  ("--size", args.size), ("--camera", args.camera), ("--bag", args.bag))
                   if v is not None] + (["--on-device"] if args.on_device else [])
    if device_only:
        raise UsageError(f"{', '.join(device_only)}: only with --device (live capture from an OAK-D)")
    missing = [n for n, v in (("LEFT", args.left), ("RIGHT", args.right), ("--rig", args.rig)) if v is None]
    if missing:
        raise UsageError(f"stereo: expected LEFT RIGHT --rig RIG.json (or --device), missing {', '.join(missing)}")
    check_output(args.out, folder=True)
    replace = claim_folder(args.out, "depth", force=args.force, inputs=[args.left, args.right, args.rig],
                           names=_DEPTH_FILES)
    run = stereo_depth_files(args.left, args.right, args.rig, args.out, method=args.method,
                             min_depth=args.min_depth, alpha=args.alpha, num_disparities=args.num_disparities,
                             progress=say)
    replace()
    result(f"wrote {args.out}/{', '.join(run.names)} ({run.n_points:,} points)")
    return 0


def _stereo_device(args: argparse.Namespace) -> int:
    from rangekit.app.commands.stereo_live import stereo_depth_device

    if args.camera == "realsense":
        return _stereo_realsense(args)
    if args.bag is not None:
        raise UsageError(f"--bag plays a RealSense recording: only with --camera realsense (found --bag {args.bag})")
    check_output(args.out, folder=True)
    replace = claim_folder(args.out, "depth", force=args.force,
                           names=_DEPTH_FILES + ("left.png", "right.png", RIG_FILE, "device_depth.*"))
    run = stereo_depth_device(args.out, device_id=args.device_id, size=args.size or (640, 400),
                              dots=0.8 if args.dots is None else args.dots,
                              flood=0.0 if args.flood is None else args.flood, on_device=args.on_device,
                              method=args.method, min_depth=args.min_depth, alpha=args.alpha,
                              num_disparities=args.num_disparities, progress=say)
    replace()
    result(f"wrote {args.out}/{', '.join(run.names)} ({run.n_points:,} points)")
    return 0


def _stereo_realsense(args: argparse.Namespace) -> int:
    """rangekit stereo --device --camera realsense [--device-id SERIAL | --bag FILE]: the camera's own depth frame."""
    from rangekit.app.commands.stereo_live import realsense_depth_device

    ours = [n for n, v in (("--flood", args.flood), ("--num-disparities", args.num_disparities)) if v is not None]
    ours += ["--on-device"] if args.on_device else []
    if ours:
        raise UsageError(f"{', '.join(ours)}: not with --camera realsense (it matches the pair on board, and has no "
                         "flood light)")
    if args.bag is not None and args.device_id is not None:
        raise UsageError(f"--bag plays a recording, --device-id chooses a camera: give one (found --bag {args.bag} "
                         f"--device-id {args.device_id})")
    check_output(args.out, folder=True)
    replace = claim_folder(args.out, "depth", force=args.force, inputs=[args.bag] if args.bag else [],
                           names=_DEPTH_FILES + (RIG_FILE,))
    run = realsense_depth_device(args.out, serial=args.device_id, bag=args.bag, size=args.size or (848, 480),
                                 laser_power=args.dots, progress=say)
    replace()
    result(f"wrote {args.out}/{', '.join(run.names)} ({run.n_points:,} points)")
    return 0


FORCE_HELP = ("write over files in --out this run did not make: another command's set (a session, a capture, "
              "results), files of yours, an input")


def add_parsers(sub) -> None:
    tofp = sub.add_parser("tof", help="time of flight: range, depth and a cloud from raw ToF samples",
                          description="Decode a ToF capture folder (rangekit sim render --sensor tof|tof-pulsed, "
                                      "layout in docs/tof.md): N-bucket phase, amplitude and offset per frequency, "
                                      "multi-frequency unwrapping, flying-pixel filter, radial range to depth.")
    tofp.add_argument("raw_dir", metavar="RAW_DIR", help=f"ToF capture folder (tof.json, {RIG_FILE}, samples/)")
    tofp.add_argument("--out", required=True, help="output folder: depth.npy (z, metres, NaN invalid), range.npy, "
                                                    f"confidence.npy/png, depth.png, {CLOUD_FILE}")
    tofp.add_argument("--force", action="store_true", help=FORCE_HELP)
    tofp.add_argument("--max-range", type=positive_float, help="metres; default the plan's unambiguous range")
    tofp.add_argument("--min-snr", type=non_negative_float, default=3.0,
                      help="drop pixels whose phase noise exceeds 1/MIN_SNR rad (default 3)")
    tofp.add_argument("--flying-angle-deg", type=positive_float, default=15.0,
                      help="flying-pixel filter threshold in degrees (default 15)")
    tofp.add_argument("--keep-flying", action="store_true", help="do not filter mixed pixels (flying, or partially "
                                                                    "covered at depth edges)")
    tofp.set_defaults(func=cmd_tof)

    stp = sub.add_parser("stereo", help="active stereo: depth of the left camera from a stereo pair (files or an OAK-D)",
                         description="Rectify a raw stereo pair with the rig file's two cameras (cameras[0] = left, "
                                     "cameras[1] = right), match it (census + semi-global matching, or OpenCV "
                                     "StereoSGBM), check left-right consistency, refine to subpixel and convert to "
                                     "depth on the left camera's own pixel grid (docs/stereo.md). With --device the "
                                     "pair is captured from an attached OAK-D and matched the same way.")
    stp.add_argument("left", metavar="LEFT", nargs="?", help="left image (PNG, 8 or 16 bit, grey or RGB)")
    stp.add_argument("right", metavar="RIGHT", nargs="?", help="right image, same size")
    stp.add_argument("--rig", help="rig file with two cameras (left first); not with --device")
    stp.add_argument("--device", action="store_true",
                     help="capture a synchronised pair from an attached OAK-D (CAM_B left, CAM_C right, dot projector "
                          f"on, flood off) with its own calibration; writes left.png, right.png and {RIG_FILE} too")
    stp.add_argument("--device-id", help="with --device: device id (MXID), name or IP (default the first found); a "
                                          "RealSense's serial number with --camera realsense")
    stp.add_argument("--camera", choices=("depthai", "realsense"),
                     help="with --device: an OAK-D (depthai, default: the pair matched here) or a RealSense (its own "
                          f"depth frame, emitter on; writes range.npy and the SDK's intrinsics in {RIG_FILE})")
    stp.add_argument("--bag", help="with --device --camera realsense: play a recording (.bag or .db3) instead of a camera")
    stp.add_argument("--dots", type=fraction, help="with --device: IR dot projector power 0..1 (default 0.8; a "
                                                   "RealSense's laser_power, default as it is)")
    stp.add_argument("--flood", type=fraction, help="with --device: IR flood light power 0..1 (default 0: off)")
    stp.add_argument("--size", type=size, help="with --device: WxH of both mono frames (default 640x400)")
    stp.add_argument("--on-device", action="store_true",
                     help="with --device: also run the camera's own StereoDepth; saves device_depth.npy/png next to "
                          "ours and prints the difference")
    stp.add_argument("--out", required=True, help="output folder: depth.npy (left z, metres, NaN invalid), depth.png, "
                                                   f"confidence.npy/png, {CLOUD_FILE}")
    stp.add_argument("--force", action="store_true", help=FORCE_HELP)
    stp.add_argument("--method", default="census-sgm", choices=("census-sgm", "sgbm"),
                     help="our census + semi-global matcher (default) or OpenCV's StereoSGBM")
    stp.add_argument("--num-disparities", type=int_in(16, 1024), help="disparity search range (multiple of 16; default from "
                                                         "--min-depth)")
    stp.add_argument("--min-depth", type=positive_float, default=0.4, help="nearest depth to search, metres (default 0.4)")
    stp.add_argument("--alpha", type=fraction, default=0.0,
                     help="rectification scaling: 0 crops to valid pixels (finer at low resolution, default), 1 keeps "
                          "every source pixel; 0.5 reaches the image borders at 640x400 (docs/stereo.md)")
    stp.set_defaults(func=cmd_stereo)
