"""``rangekit decode`` and ``rangekit reconstruct``: coded structured light."""

from __future__ import annotations

import argparse
import time

from rangekit.cli._common import check_beside, check_output, console, finite_float, note, result, say, size
from rangekit.formats.sessions.files import MAPS_FILE, PATTERNS_FILE, RIG_FILE


def cmd_decode(args: argparse.Namespace) -> int:
    """rangekit decode IMAGES --pattern SPEC_OR_NAME --projector WxH [--order opencv] --out maps.npz"""
    from pathlib import Path

    from rangekit.coded.decode import decode
    from rangekit.errors import naming
    from rangekit.formats.capture import list_images, pattern_spec_for, read_stack, save_decoded
    from rangekit._runtime.memory import reuse_freed_memory

    t0 = time.perf_counter()
    from rangekit.formats.capture import DECODED_SUFFIXES

    check_output(args.out, suffixes=DECODED_SUFFIXES, what="decoded maps", force=args.force,
                 inputs=list(args.images) + ([args.pattern] if ":" not in args.pattern else []))
    if ":" in args.pattern:
        return _decode_layout(args, t0)
    paths = list_images(args.images[0] if len(args.images) == 1 else args.images)
    spec = pattern_spec_for(args.pattern, args.projector)
    note(f"reading {len(paths)} images")
    with reuse_freed_memory():   # the decoder's temporaries reuse pages (rangekit._runtime.memory)
        images = read_stack(paths)
        note(f"decoding {spec.method} ({'subpixel' if not args.integer else 'integer'})")
        with naming(args.images[0] if len(args.images) == 1 else f"{len(paths)} images from {paths[0]}"):
            res = decode(images, spec, order=args.order, subpixel=not args.integer, motion=True,
                         max_motion=args.max_motion)
        del images
    save_decoded(args.out, res, compress=args.compress)
    say(f"{res!r}")
    result(f"wrote {Path(args.out)} in {time.perf_counter() - t0:.1f} s")
    return 0


def _decode_layout(args: argparse.Namespace, t0: float) -> int:
    """``rangekit decode DIR --pattern PRESET --projector WxH``: another tool's folder as it lies on disk, the maps
    in its projector's pixels (:func:`rangekit.formats.layouts.in_projector_pixels`)."""
    from pathlib import Path

    from rangekit.coded.decode import decode
    from rangekit.errors import UsageError, naming
    from rangekit.formats.capture import read_stack, save_decoded
    from rangekit.formats.layouts import LAYOUTS, arrange, capture_frames, in_projector_pixels

    if args.pattern not in LAYOUTS:
        raise UsageError(f"--pattern {args.pattern}: not a capture layout; known: {', '.join(sorted(LAYOUTS))}")
    if args.projector is None:
        raise UsageError(f"--pattern {args.pattern} reads one camera's capture and needs --projector WxH (the size "
                         "the tool projected at)")
    layout, (width, height) = LAYOUTS[args.pattern], args.projector
    (found,) = capture_frames(args.images, layout, width, height)
    say(found.line())
    frames = read_stack(found.files, what=f"a {layout.name} capture")
    stack, spec = arrange(list(frames), layout, width, height)
    del frames
    note(f"decoding {layout.name} ({layout.source})")
    with naming(found.source):
        res = decode(stack, spec, subpixel=not args.integer, motion=True, max_motion=args.max_motion,
                     **layout.view_options.get("decode_options", {}))
    res = in_projector_pixels(res, layout, width, height)
    save_decoded(args.out, res, compress=args.compress)
    say(f"{res!r}")
    result(f"wrote {Path(args.out)} in {time.perf_counter() - t0:.1f} s")
    return 0


def cmd_reconstruct(args: argparse.Namespace) -> int:
    """rangekit reconstruct CAPTURE_DIR [--rig RIG.json ...] --out cloud.ply"""
    from pathlib import Path

    from rangekit.app.commands.reconstruct import reconstruct_checked
    from rangekit.app.commands.rig_choice import load_rigs
    from rangekit.errors import ConfigError, UsageError
    from rangekit.formats.capture import load_capture
    from rangekit.formats.dots_capture import is_dots_capture
    from rangekit.formats.laser_capture import is_laser_capture, is_laser_stereo_capture
    from rangekit.formats.clouds import CLOUD_WRITERS, save_cloud

    t0 = time.perf_counter()
    check_output(args.out, suffixes=CLOUD_WRITERS, what="point cloud", force=args.force,
                 inputs=list(args.capture) + list(args.rig or []))
    if not args.no_refine:   # the refined rig and its figures, when the capture refines the rig
        stem = Path(args.out).stem
        check_beside(args.out, (f"{stem}.refined-rig.json", f"{stem}.refinement.json"), force=args.force,
                     inputs=list(args.capture) + list(args.rig or []))
    from rangekit.formats.layouts.laser import LASER_LAYOUTS

    if args.pattern in LASER_LAYOUTS:
        return _reconstruct_laser_recording(args, t0)
    if args.step_deg is not None:
        raise UsageError(f"--step-deg: only with --pattern laser:... (a recorded laser scan: {', '.join(LASER_LAYOUTS)})")
    if args.pattern is not None:
        return _reconstruct_layout(args, t0)
    if len(args.capture) != 1:
        raise UsageError(f"two captures ({' '.join(map(str, args.capture))}) are read only with --pattern PRESET "
                         "(two cameras under another tool's layout, docs/real-captures.md)")
    if args.projector is not None:
        raise UsageError("--projector WxH is for --pattern PRESET with a rig of two cameras; a capture folder's "
                         "pattern set gives the projector's size")
    args.capture = args.capture[0]
    rigs_given = args.rig
    one_rig = args.rig[0] if args.rig else None
    if args.rig and len(args.rig) > 1 and not (Path(args.capture) / PATTERNS_FILE).is_file():
        raise UsageError(f"--rig: several rigs ({' '.join(args.rig)}) are ranked only for coded-light captures; "
                         f"{args.capture} is not one")
    args.rig = one_rig
    if is_laser_stereo_capture(args.capture):   # a laser sheet seen by two cameras
        return _reconstruct_laser_stereo(args, t0)
    if args.pair_only:
        raise UsageError(f"--pair-only: only for a two-camera laser capture (capture.json kind "
                         f"'rangekit.laser_stereo/1'); {args.capture} is not one")
    if is_laser_capture(args.capture):
        return _reconstruct_laser(args, t0)
    if is_dots_capture(args.capture):   # one camera, a dot projector and its reference image
        from rangekit.app.commands.ranges import dots_depth_folder
        from rangekit.surface.cloud import PointCloud

        res = dots_depth_folder(args.capture, rig_file=args.rig, progress=say)
        save_cloud(args.out, PointCloud(res.points))
        result(f"wrote {len(res.points)} points to {args.out} in {time.perf_counter() - t0:.1f} s")
        return 0
    cap = load_capture(args.capture)
    if cap.spec is None:
        raise ConfigError(f"{args.capture}: no {PATTERNS_FILE}; decode the images with 'rangekit decode' and a "
                          "--pattern, or add the pattern spec to the folder")
    if rigs_given:
        rigs = load_rigs(rigs_given, report=note)
    elif cap.rig is not None and cap.rig.projector is not None:
        rigs = [(str(Path(args.capture) / RIG_FILE), cap.rig)]
    else:
        raise ConfigError(f"{args.capture}: no {RIG_FILE} with a projector; pass --rig RIG.json")
    note(f"decoding {len(cap.images)} images ({cap.spec.method})")
    checked = reconstruct_checked(cap, rigs, subpixel=not args.integer, method=args.method, refine=not args.no_refine,
                                  free_intrinsics=args.refine_lens, max_motion=args.max_motion)
    rec = checked.reconstruction
    save_cloud(args.out, rec.cloud)
    say(f"{rec.decoded!r}")
    _rig_lines(args, checked)
    say(f"{rec.triangulated!r}")
    result(f"wrote {len(rec.cloud)} points to {args.out} in {time.perf_counter() - t0:.1f} s")
    return 0


def _rig_lines(args: argparse.Namespace, checked, to_rig_projector=None) -> None:
    """The rig check's lines, and the refined rig written beside the cloud when there is one."""
    from rangekit.app.commands.rig_choice import refined_rig_files

    for line in checked.lines():
        note(line)
    if checked.refined.refinement is not None:
        rig_path, figures_path = refined_rig_files(args.out, checked.choice.rig, checked.refined,
                                                   to_rig_projector=to_rig_projector)
        note(f"wrote the refined rig to {rig_path} (its figures: {figures_path})")


def _reconstruct_layout(args: argparse.Namespace, t0: float) -> int:
    """``rangekit reconstruct DIR [DIR2] --pattern PRESET --rig RIG.json [--projector WxH]``: another tool's capture
    as it lies on disk (:mod:`rangekit.formats.layouts`), one camera with a projector or two cameras."""
    from rangekit.app.commands.reconstruct import reconstruct_tool_capture
    from rangekit.errors import UsageError
    from rangekit.formats.clouds import save_cloud
    from rangekit.app.commands.rig_choice import load_rigs
    from rangekit.formats.layouts import LAYOUTS, from_decoding_projector

    if not args.rig:
        raise UsageError(f"--pattern {args.pattern}: give the rig with --rig RIG.json (e.g. from 'rangekit rig "
                         "import' of the tool's calibration)")
    rigs = load_rigs(args.rig, report=note)
    layout = LAYOUTS[args.pattern]
    note(f"reading {layout.name} ({layout.source})")
    checked = reconstruct_tool_capture(args.capture, args.pattern, rigs, projector_size=args.projector,
                                       subpixel=not args.integer, method=args.method, report=say,
                                       refine=not args.no_refine, free_intrinsics=args.refine_lens,
                                       max_motion=args.max_motion)
    rec = checked.reconstruction
    save_cloud(args.out, rec.cloud)
    say(f"{rec.decoded!r}")
    rig = checked.choice.rig
    _rig_lines(args, checked, None if rig.projector is None else
               lambda p: from_decoding_projector(p, rig.projector, layout))
    result(f"wrote {len(rec.cloud)} points to {args.out} in {time.perf_counter() - t0:.1f} s")
    return 0


def _reconstruct_laser(args: argparse.Namespace, t0: float) -> int:
    """``rangekit reconstruct`` of a laser capture folder (off.png, laser0.png, ...): see docs/laser.md."""
    from rangekit.app.laser.reconstruct import reconstruct_laser_capture
    from rangekit.formats.clouds import save_cloud
    from rangekit.formats.laser_capture import load_laser_capture
    from rangekit.rig.rig_file import load_rig

    cap = load_laser_capture(args.capture, rig=load_rig(args.rig) if args.rig else None)
    note(f"laser capture: {len(cap.frames)} laser(s); line peaks ({args.peaks}) and ray-plane triangulation")
    rec = reconstruct_laser_capture(cap, method=args.peaks)
    save_cloud(args.out, rec.cloud)
    say(rec.summary())
    result(f"wrote {len(rec.cloud)} points to {args.out} in {time.perf_counter() - t0:.1f} s")
    return 0


def _reconstruct_laser_recording(args: argparse.Namespace, t0: float) -> int:
    """``rangekit reconstruct DIR --pattern laser:... --rig RIG.json [--step-deg DEG]``: a recorded laser-line
    turntable scan, every step on the rig's laser planes, turned back by its angle, the lasers merged (docs/laser.md,
    "A webcam laser rig from recorded frames")."""
    from rangekit.app.laser.recording import reconstruct_laser_recording, recording_lines
    from rangekit.errors import UsageError
    from rangekit.formats.clouds import save_cloud
    from rangekit.formats.layouts.laser import read_laser_recording
    from rangekit.rig.rig_file import load_rig

    given = [f for f, v in (("--projector", args.projector is not None), ("--pair-only", args.pair_only),
                            ("--refine-lens", args.refine_lens)) if v]
    if given:
        raise UsageError(f"{given[0]}: not with --pattern {args.pattern} (a recorded laser scan)")
    if len(args.capture) != 1:
        raise UsageError(f"--pattern {args.pattern}: one recording folder, found {len(args.capture)}")
    if not args.rig or len(args.rig) != 1:
        raise UsageError(f"--pattern {args.pattern}: give the laser rig with --rig RIG.json (one; from 'rangekit "
                         "calibrate --lasers --captures ...')")
    recording = read_laser_recording(args.capture[0], args.pattern, step_deg=args.step_deg)
    say(recording.line())
    rig = load_rig(args.rig[0])
    if not rig.lasers:
        raise UsageError(f"--rig {args.rig[0]}: no 'lasers'; calibrate them with rangekit calibrate --lasers")
    rec = reconstruct_laser_recording(recording, rig, method=args.peaks, progress=console())
    save_cloud(args.out, rec.cloud)
    say(rec.summary())
    for line in recording_lines(recording, rec):
        say(line)
    result(f"wrote {len(rec.cloud)} points to {args.out} in {time.perf_counter() - t0:.1f} s")
    return 0


def _reconstruct_laser_stereo(args: argparse.Namespace, t0: float) -> int:
    """``rangekit reconstruct`` of a two-camera laser capture folder (left/, right/): see docs/laser.md."""
    from pathlib import Path

    from rangekit.app.laser.sheet_stereo import reconstruct_laser_stereo_capture, report_laser_stereo_truth
    from rangekit.errors import UsageError, naming
    from rangekit.formats.clouds import save_cloud
    from rangekit.formats.laser_capture import load_laser_stereo_capture
    from rangekit.stereo.rectify import rectify

    if args.peaks == "ridge":
        raise UsageError("--peaks ridge: a two-camera laser capture needs one peak per row (gaussian, com or argmax)")
    cap = load_laser_stereo_capture(args.capture, rig=args.rig)
    note(f"two-camera laser capture: {cap.n_lasers} laser(s); line peaks ({args.peaks}) in both cameras, matched on "
         "epipolar lines and triangulated by the pair (no laser plane)"
         + ("" if args.pair_only else "; the left peaks the right camera misses met with each frame's fitted sheet"))
    with naming(args.rig or Path(args.capture) / RIG_FILE):   # a pair that cannot be rectified
        rect = rectify(*cap.rig.cameras[:2])
    rec = reconstruct_laser_stereo_capture(cap, method=args.peaks, rect=rect, fill=not args.pair_only)
    if rec.pairing_line():
        note(rec.pairing_line())
    save_cloud(args.out, rec.cloud)
    say(rec.summary())
    report_laser_stereo_truth(cap, rec, progress=say)
    result(f"wrote {len(rec.cloud)} points to {args.out} in {time.perf_counter() - t0:.1f} s")
    return 0


def _share(text: str) -> float | None:
    """``--max-motion``: a percentage ("2%" or "2"), or "none"."""
    if text.strip().lower() == "none":
        return None
    try:
        value = float(text.strip().rstrip("%")) / 100.0
    except ValueError:
        value = float("nan")
    if not 0.0 <= value <= 1.0:
        raise argparse.ArgumentTypeError(f"expected a percentage from 0 to 100 or 'none', found {text!r}")
    return value


def add_parsers(sub) -> None:
    from rangekit.coded.motion import MAX_MOTION_SHARE
    from rangekit.coded.patterns import PATTERN_METHODS
    from rangekit.formats.layouts import LAYOUTS as CAPTURE_LAYOUTS
    from rangekit.formats.layouts.laser import LASER_LAYOUTS

    dec = sub.add_parser("decode", help=f"decode coded-light images into projector coordinates ({MAPS_FILE})",
                         description="Decode a capture into per-pixel projector column/row maps with confidence.")
    dec.add_argument("images", nargs="+", metavar="IMAGES",
                     help="a folder (images taken in natural numeric order) or a list of image files")
    dec.add_argument("--pattern", required=True,
                     help=f"pattern method ({', '.join(PATTERN_METHODS)}), a {PATTERNS_FILE} spec file, or another "
                          f"tool's capture layout ({', '.join(sorted(CAPTURE_LAYOUTS))}; docs/real-captures.md)")
    dec.add_argument("--projector", type=size, help="projector resolution WxH, e.g. 1280x800")
    dec.add_argument("--order", default="rangekit", choices=("rangekit", "opencv"),
                     help="capture order; 'opencv' = GrayCodePattern (pairs, then white, black)")
    dec.add_argument("--integer", action="store_true", help="integer codes only (no subpixel refinement)")
    dec.add_argument("--compress", action="store_true",
                     help="deflate the .npz (6x smaller, 0.2 CPU-s more at 2048x1500); default: stored as np.savez")
    dec.add_argument("--max-motion", type=_share, default=MAX_MOTION_SHARE, metavar="PERCENT",
                     help="binary codes: refuse the capture when more than this share of the decoded pixels moved "
                          f"during it (the 'motion' mask; default {MAX_MOTION_SHARE * 100:.0f}%%; 'none': never refuse)")
    dec.add_argument("--out", required=True, help="output .npz with proj_col, proj_row, confidence and masks")
    dec.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    dec.set_defaults(func=cmd_decode)

    rec = sub.add_parser("reconstruct", help="decode and triangulate a capture folder into a point cloud",
                         description="Decode a capture folder (from 'rangekit sim render' or acquisition) and "
                                     "triangulate it against the projector into a coloured cloud with normals; "
                                     "a laser capture (off.png, laser0.png, ...) is triangulated against the "
                                     "rig file's laser planes, a two-camera one (left/, right/) by the camera pair.")
    rec.add_argument("capture", metavar="CAPTURE_DIR", nargs="+",
                     help=f"capture folder (images + {PATTERNS_FILE}); with --pattern, another tool's folder (its own "
                          "names, or any names in numeric order), two folders (camera 1, camera 2), image files or "
                          "a quoted glob ('caps/*.png'; one per camera), or OpenCV's image list")
    rec.add_argument("--rig", nargs="+", metavar="RIG",
                     help=f"rig file (default: the folder's {RIG_FILE}); several: each checked against the capture, the "
                          "one that fits best used and the ranking printed (another tool's calibration file is "
                          "imported on the way, as 'rangekit rig import' would)")
    rec.add_argument("--no-refine", action="store_true",
                     help="keep the rig as given when it does not fit the capture (default: its projector's or second "
                          "camera's pose refined from the capture, written beside --out as NAME.refined-rig.json)")
    rec.add_argument("--max-motion", type=_share, default=MAX_MOTION_SHARE, metavar="PERCENT",
                     help="binary codes: refuse the capture when more than this share of the decoded pixels moved "
                          f"during it, as 'rangekit decode' does (default {MAX_MOTION_SHARE * 100:.0f}%%; 'none')")
    rec.add_argument("--refine-lens", action="store_true",
                     help="refine the projector's (or second camera's) focal length too (two views cannot fix its principal point)")
    rec.add_argument("--pattern", choices=sorted(CAPTURE_LAYOUTS) + list(LASER_LAYOUTS), default=None,
                     help="another tool's capture layout, read as it lies on disk (docs/real-captures.md); needs "
                          "--rig; laser:... a recorded laser-line turntable scan (docs/laser.md)")
    rec.add_argument("--step-deg", type=finite_float, default=None,
                     help="with --pattern laser:...: the turntable's step between the recorded steps, degrees (a "
                          "recording with a steps.csv gives each step's angle instead)")
    rec.add_argument("--projector", type=size, default=None,
                     help="with --pattern and a rig of two cameras: the projector's size WxH the tool projected at")
    rec.add_argument("--method", default="auto", choices=("auto", "ray-plane", "ray-ray"),
                     help="triangulation; auto = ray-ray where rows are coded, else ray-plane")
    rec.add_argument("--integer", action="store_true", help="integer codes only (no subpixel refinement)")
    rec.add_argument("--peaks", default="gaussian", choices=("gaussian", "com", "ridge", "argmax"),
                     help="laser captures: the line peak detector (default gaussian, docs/laser.md)")
    rec.add_argument("--pair-only", action="store_true",
                     help="two-camera laser captures: only the points the camera pair triangulates (default: also the "
                          "left peaks the right camera does not see, met with the light sheet fitted to that frame's "
                          "pair points; docs/laser.md)")
    rec.add_argument("--out", required=True, help="output cloud (.ply, .pcd, .xyz, .npy or .e57; checked before any work)")
    rec.add_argument("--force", action="store_true",
                     help="overwrite --out (and the refined rig written beside it) if it exists")
    rec.set_defaults(func=cmd_reconstruct)
