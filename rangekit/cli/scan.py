"""``rangekit scan`` and ``rangekit process``: a turntable session, acquired (resumable) and processed."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from rangekit.cli._common import (LazyChoices, LazyHelp, check_output, console, finite_float, int_in, lazy_help, note,
                                  option_range, result, say, scheduler_address)
from rangekit.errors import UsageError
from rangekit.formats.sessions.files import (MERGED_FILE, MESH_FILE, POSES_FILE, REPORT_FILE, SUMMARY_FILE,
                                             WATERTIGHT_FILE)


def cmd_scan(args: argparse.Namespace) -> int:
    """rangekit scan --out DIR | --resume DIR [--method coded|laser] [--rig sim|RIG.json] [--object lumpy]
    [--views 12 | --steps 400] [--passes 2 [--flipped]] [--patterns hybrid-8step-min3] [--up X Y Z] [--allow-auto-exposure]:
    :func:`rangekit.app.scan.scan.scan` with these options, its events shown as it runs."""
    from rangekit.app.scan.options import SCAN_FLAGS
    from rangekit.app.scan.scan import scan
    from rangekit.errors import OptionError

    if args.out is not None or args.resume is not None:
        check_output(args.resume if args.out is None else args.out, option="--out" if args.resume is None else
                     "--resume", folder=True, session=args.resume is not None)
    shown = _ScanPrinter(args, time.perf_counter())
    try:
        options = scan_options(args)
        res = scan(options, on_event=shown)
    except OptionError as exc:
        raise exc.named(SCAN_FLAGS) from None
    except KeyboardInterrupt:
        folder = args.resume or args.out
        if shown.processing:
            print(f"rangekit: interrupted; the views decoded so far are cached. Continue with: "
                  f"rangekit scan --resume {folder}", file=sys.stderr)
        else:
            print(f"rangekit: interrupted; completed views are safe. Continue with: rangekit scan --resume {folder}",
                  file=sys.stderr)
        return 130
    if res.vdi2634 is not None:
        from rangekit.app.scan.vdi2634 import figure_lines

        say("")
        for line in figure_lines(res.vdi2634):
            say(line)
        result(f"wrote {args.out}/vdi2634.json in {res.seconds:.1f} s")
        return 0
    if res.processed is None:
        say(f"process it later with: rangekit process {res.folder}")
        return 0
    _print_processed(res.folder, res.processed, options.processing, res.seconds,
                     acquisition_s=res.acquisition_seconds)
    return 0


def _exposures(text: str):
    """Argument type of --exposures: 'auto' or microseconds 1..1000000."""
    return text if text == "auto" else int_in(1, 1_000_000)(text)


def _bump(text: str):
    """Argument type of --sim-bump: VIEW:FRAME:MM."""
    try:
        view, frame, mm = text.split(":")
        return int(view), int(frame), float(mm)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected VIEW:FRAME:MM, e.g. 3:30:0.5, found {text!r}") from None


#: ``rangekit process``'s flags that are not options of one session's processing: the sessions themselves and the
#: Dask batch's (a scan processes its one session in this process).
BATCH_ONLY = ("session", "scheduler", "workers")
#: ScanOptions' fields that are ``processing``'s shorthands (their flags are ``processing``'s, shared by both
#: commands: :func:`_processing_options`).
_SHORTHANDS = ("fusion", "report", "format")


def scan_options(args: argparse.Namespace):
    """The :class:`rangekit.app.scan.options.ScanOptions` of ``rangekit scan``'s parsed flags (one field per flag,
    :data:`rangekit.app.scan.options.SCAN_FLAGS`; ``--no-process`` negated; the processing flags make
    ``processing``, :func:`process_options`)."""
    from rangekit.app.scan.options import SCAN_FIELDS, ScanOptions
    from rangekit.errors import OptionError

    values = {name: getattr(args, name) for name in SCAN_FIELDS
              if name not in ("process", "processing", *_SHORTHANDS)}
    values.update(process=not args.no_process)
    for name in ("up", "positions", "exposures"):
        if values[name] is not None:
            values[name] = tuple(values[name])
    from rangekit.app.scan.options import SCAN_FUSION

    try:   # a coded-light scan fuses by blocks unless --fusion says otherwise (ScanOptions' SCAN_FUSION)
        processing = process_options(args, fusion="poisson" if values.get("method") == "laser" else SCAN_FUSION)
    except OptionError as exc:
        raise exc.within("processing") from None
    return ScanOptions(**values, processing=processing)


class _ScanPrinter:
    """The command line's subscriber to a scan's events: the resume note and the exposures before acquiring, the
    progress bar, the acquisition line once every view is on disk."""

    def __init__(self, args: argparse.Namespace, t0: float) -> None:
        from rangekit.app.events import progress_subscriber

        self._args, self._t0, self._started = args, t0, None
        self._progress = progress_subscriber(console())
        self.processing = False

    def __call__(self, event) -> None:
        from rangekit.app.events import ScanStarted, StageFinished, StageStarted

        if isinstance(event, ScanStarted):
            self._started = event
            if event.exposures_us and self._args.exposures == ["auto"]:
                say(f"--exposures auto: {' '.join(map(str, event.exposures_us))} us (from rangekit check's statistics)")
            if event.resume:
                note(f"resuming {event.folder}: {event.done}/{event.total} views already done")
        elif isinstance(event, StageFinished) and event.stage == "acquire":
            s = self._started
            (say if not self._args.no_process else result)(
                f"acquired {s.total} {'steps' if s.laser else 'views'} x {s.n_frames} frames into {s.folder} in "
                f"{time.perf_counter() - self._t0:.1f} s")
        elif isinstance(event, StageStarted) and event.stage != "acquire":
            self.processing = True
        if self._progress is not None:
            self._progress(event)


def process_options(args: argparse.Namespace, fusion: str | None = None):
    """The :class:`rangekit.app.process.options.ProcessOptions` of the processing flags given (those of
    :func:`_processing_options`, on both commands; a flag ``--no-X`` negated); the others take the dataclass's
    defaults, the one place they are written, but the fusion when ``fusion`` is given (``rangekit scan``'s)."""
    from rangekit.app.process.options import PROCESS_FLAGS, ProcessOptions

    given = {}
    for field, flag in PROCESS_FLAGS.items():
        dest = flag.lstrip("-").replace("-", "_")
        if hasattr(args, dest):
            given[field] = not getattr(args, dest) if flag.startswith("--no-") else getattr(args, dest)
    if fusion is not None:
        given.setdefault("fusion", fusion)
    return ProcessOptions(**given)


def _process(folder: str, args: argparse.Namespace, options) -> int:
    from rangekit.app.events import progress_subscriber
    from rangekit.app.scan.scan import process

    t0 = time.perf_counter()
    try:
        res = process(folder, options, on_event=progress_subscriber(console()))
    except KeyboardInterrupt:
        print(f"rangekit: interrupted; the views decoded so far are cached. Continue with: rangekit process {folder}",
              file=sys.stderr)
        return 130
    _print_processed(Path(folder), res, options, time.perf_counter() - t0)
    return 0


def _print_processed(folder: Path, res, options, seconds: float, *, acquisition_s: float | None = None) -> None:
    """The end-of-run summary and the files written."""
    from rangekit.progress import format_seconds

    say("")
    say(f"== {folder}: summary ==")
    if acquisition_s is not None:
        say(f"acquisition: {format_seconds(acquisition_s)}")
    for line in res.summary_lines():
        say(line)
    fmt = options.mesh_format
    exported = [] if fmt == "ply" else [f"mesh.{fmt}", f"mesh_watertight.{fmt}"]
    result(f"wrote {folder}/{MESH_FILE} (observed surface), {WATERTIGHT_FILE} (closed), "
           + "".join(f"{name}, " for name in exported) + f"{MERGED_FILE}, {POSES_FILE}, {SUMMARY_FILE}"
           + (f", {REPORT_FILE}" if options.report else "") + f" in {format_seconds(seconds)}")


def cmd_process(args: argparse.Namespace) -> int:
    """rangekit process DIR [DIR ...] [--fusion poisson|tsdf] [--scheduler local|ADDRESS] [--workers N]: decode,
    register and fuse each session into DIR/mesh.ply; several sessions (or --scheduler) on Dask"""
    from rangekit.app.process.options import PROCESS_FLAGS
    from rangekit.errors import OptionError

    try:
        options = process_options(args)
    except OptionError as exc:
        raise exc.named(PROCESS_FLAGS) from None
    if len(args.session) == 1 and args.scheduler is None:
        if args.workers is not None:
            raise UsageError(f"--workers: Dask workers for several sessions or --scheduler; found {args.workers} "
                             "with one session and no --scheduler (give --scheduler local, or leave --workers out)")
        check_output(args.session[0], option="DIR", folder=True, session=True)
        return _process(args.session[0], args, options)
    return _process_batch(args, options)


def _process_batch(args: argparse.Namespace, options) -> int:
    """Several sessions on Dask (rangekit.app.batch.sessions): a line per view and session, then each session done or
    failed; exit 1 when any failed."""
    from rangekit.app.batch.sessions import process_sessions
    from rangekit.progress import format_seconds

    scheduler = args.scheduler or "local"
    if scheduler != "local" and args.workers is not None:
        raise UsageError(f"--workers: the number of workers of --scheduler local; the scheduler at {scheduler} has "
                         f"its own workers, found --workers {args.workers}; leave it out")
    if len(set(Path(s).resolve() for s in args.session)) != len(args.session):
        raise UsageError(f"DIR: expected different session folders, found one given twice in {' '.join(args.session)}")
    for s in args.session:
        check_output(s, option="DIR", folder=True)
    from rangekit._runtime.executor import worker_count

    workers = worker_count(args.workers or 0)
    where = f"a local cluster of {workers} worker processes" if scheduler == "local" else scheduler
    note(f"processing {len(args.session)} session(s) on {where}")
    try:
        res = process_sessions(args.session, options, scheduler=scheduler, workers=workers,
                               progress=console())
    except KeyboardInterrupt:
        print(f"rangekit: interrupted; the views decoded so far are cached. Continue with: rangekit process "
              f"{' '.join(args.session)}", file=sys.stderr)
        return 130
    say("")
    result(f"== {len(res.sessions) - len(res.failed)} of {len(res.sessions)} session(s) processed in "
        f"{format_seconds(res.seconds)} ==")
    for o in res.sessions:
        if o.ok:
            say(f"{o.folder}: done ({o.views_decoded} views decoded, {o.views_cached} from the cache); "
                + (o.summary[0] if o.summary else ""))
        else:
            result(f"{o.folder}: FAILED: {o.error}")
    return 1 if res.failed else 0


def processing_help() -> dict:
    """The values the processing flags' help shows, from :class:`~rangekit.app.process.options.ProcessOptions` (read
    when help is shown: :class:`rangekit.cli._common.LazyHelp`)."""
    from rangekit._runtime.option_fields import default_of, specs
    from rangekit.app.process.options import POISSON_DEFAULTS, ProcessOptions

    depth = specs(ProcessOptions)["poisson_depth"]
    return {"fusion": default_of(ProcessOptions, "fusion"), "format": default_of(ProcessOptions, "mesh_format"),
            "depth_lo": depth.lo, "depth_hi": depth.hi,
            "depths": ", ".join(f"{d} for {m}" for m, (d, _) in POISSON_DEFAULTS.items()),
            "motion": f"{default_of(ProcessOptions, 'max_motion') * 100:g}"}


def _processing_options(p: argparse.ArgumentParser) -> None:
    """The processing flags, the same on ``rangekit scan`` and ``rangekit process``: one per flag of
    :data:`rangekit.app.process.options.PROCESS_FLAGS`, its range and default read from
    :class:`~rangekit.app.process.options.ProcessOptions` when a value is parsed or help shown (building the
    parser imports no ``rangekit.app``); no argparse default: a flag left out is a field left out
    (:func:`process_options`)."""
    from rangekit.cli.coded import _share

    given, values, options = argparse.SUPPRESS, "rangekit.cli.scan:processing_help", \
        "rangekit.app.process.options:ProcessOptions"
    lazy_help(p.add_argument("--fusion", default=given, choices=LazyChoices("rangekit.app.process.options",
                                                                            "FUSION_METHODS"),
                             metavar="{poisson,tsdf,blocks}",
                             help="fusion into one mesh: poisson (screened Poisson of the merged cloud), tsdf, or "
                                  "blocks (the sparse volume a scan fills as its views come, cut to the points and "
                                  "projected onto them); default {fusion} (rangekit scan: blocks)"), values)
    p.add_argument("--no-report", action="store_true", default=given, help=f"skip {REPORT_FILE}")
    lazy_help(p.add_argument("--format", default=given,
                             choices=LazyChoices("rangekit.app.process.fused_outputs", "MESH_EXPORT_FORMATS"),
                             metavar="{ply,obj,stl,glb}",
                             help=f"mesh files: ply ({MESH_FILE} and {WATERTIGHT_FILE}, with vertex normals and the "
                                  "'observed' flag) or obj, stl, glb written beside them as mesh.FMT and "
                                  "mesh_watertight.FMT; default {format}"), values)
    lazy_help(p.add_argument("--poisson-depth", type=option_range(options, "poisson_depth"), default=given,
                             metavar="DEPTH",
                             help="screened Poisson's octree depth, {depth_lo}..{depth_hi} (default the method's: "
                                  "{depths}; each step up quadruples the mesh and about triples the fusion's time)"),
              values)
    lazy_help(p.add_argument("--max-motion", type=_share, default=given, metavar="PERCENT",
                             help="refuse a view in which more than this share of the decoded pixels moved during "
                                  "its capture (default {motion}%%; 'none': not checked; rangekit.coded.motion)"),
              values)


def scan_help() -> dict:
    """The values ``rangekit scan``'s help shows: a new scan's defaults
    (:data:`rangekit.app.scan.options.SCAN_DEFAULTS`)."""
    from rangekit.app.scan.options import SCAN_DEFAULTS

    return dict(SCAN_DEFAULTS)


def add_parsers(sub) -> None:
    options, values = "rangekit.app.scan.options:ScanOptions", "rangekit.cli.scan:scan_help"

    scan = sub.add_parser("scan", help="scan: acquire a turntable session (resumable), then process it into a mesh",
                          formatter_class=LazyHelp,
                          description="Acquire a crash-safe scan session (every turntable view, every pattern; "
                                      "--resume continues an interrupted one without redoing finished views), then "
                                      f"decode, register and fuse it into DIR/{MESH_FILE}.")
    where = scan.add_mutually_exclusive_group(required=True)  # --artefact takes --out
    where.add_argument("--out", help="new session folder")
    where.add_argument("--resume", metavar="DIR", help="continue the session in DIR")
    # No argparse defaults: a resumed scan takes the session's settings, and an option given with --resume
    # must equal them (rangekit.app.scan.options.SCAN_DEFAULTS fills in a new scan).
    scan.add_argument("--method", choices=("coded", "laser"),
                      help="coded (default: projector patterns, views registered) or laser (the rig's line lasers, "
                           "switched by the turntable board, one profile per turntable step)")
    lazy_help(scan.add_argument("--steps", type=option_range(options, "steps"),
                                help="turntable steps over a full turn of a laser scan (default {steps})"), values)
    scan.add_argument("--up", type=finite_float, nargs=3, metavar=("X", "Y", "Z"),
                      help="a mesh file object's up direction, stood upright on the turntable (Stanford scans: 0 1 0)")
    scan.add_argument("--rig", help="'sim' (default) or a rig file whose 'devices' name the turntable, projector and "
                                    "camera")
    lazy_help(scan.add_argument("--object", help="simulated object: built-in name (default {object}) or mesh file "
                                                 "(copied into the session)"), values)
    lazy_help(scan.add_argument("--views", type=option_range(options, "views"),
                                help="turntable views over a full turn (default {views})"), values)
    lazy_help(scan.add_argument("--passes", type=option_range(options, "passes"),
                                help="turntable passes of --views views each, the object turned over between them to "
                                     "see its bottom (default {passes}; the simulator turns it over itself, a real rig "
                                     "asks)"), values)
    scan.add_argument("--flipped", action="store_true",
                      help="with --resume: the object has been turned over for the next pass (no terminal to ask on)")
    # No choices: the named sets live in rangekit.app (not imported to build the parser); ScanOptions names them.
    lazy_help(scan.add_argument("--patterns", metavar="PATTERNS",
                                help="pattern set: a method (rangekit.coded.patterns.PATTERN_METHODS) or a named set "
                                     "(rangekit.app.scan.presets.PRESETS, docs/coded-light.md 'Frames against "
                                     "accuracy'; default {patterns}: Gray code of 8 px blocks + phase shift, 48 frames)"), values)
    scan.add_argument("--target-mm", type=finite_float, metavar="MM",
                      help="the patterns of fewest frames whose measured accuracy meets MM: one view's points at most "
                           "MM RMS against the simulator's truth (docs/coded-light.md, 'Frames against accuracy'; "
                           "not with --patterns)")
    lazy_help(scan.add_argument("--seed", type=option_range(options, "seed"),
                                help="simulator noise seed (default {seed})"), values)
    scan.add_argument("--artefact", choices=("vdi2634",),
                      help="simulator: scan the VDI/VDE 2634-2 artefacts (sphere, ball bar, plane; one view per "
                           "position) with the rig calibrated by 'rangekit calibrate' (--rig RIG.json, else calibrated "
                           "first, ~4 min) and the true rig, print PF, PS, SD, F and write DIR/vdi2634.json")
    scan.add_argument("--positions", type=int, nargs=3, metavar=("SPHERES", "BARS", "PLANES"),
                      help="with --artefact: positions of each artefact (default the guideline's 10 7 6)")
    scan.add_argument("--allow-auto-exposure", action="store_true",
                      help="scan although the rig file's capture.camera.exposure_us is 'auto' (refused otherwise: "
                           "auto-exposure changes the brightness between frames and breaks decoding)")
    scan.add_argument("--exposures", nargs="+", type=_exposures, metavar="US",
                      help="multi-exposure (HDR): capture every pattern at each exposure (microseconds, e.g. 2000 "
                           "8000 32000) and decode each pixel from its longest unsaturated one; 'auto' picks three "
                           "4x apart from rangekit check's statistics")
    scan.add_argument("--no-process", action="store_true", help="acquire only (process later with 'rangekit process')")
    scan.add_argument("--realtime", action="store_true",
                      help="the simulator keeps real time: the projector's latency, the turntable's speed and "
                           "settling, the camera's frame rate (as long as a real rig takes). A new coded-light scan "
                           "models the rig we recommend, the camera triggered by the projector's VSYNC (as "
                           "--triggered: no pattern delay; the frames are the same bytes, only the time changes)")
    scan.add_argument("--triggered", action="store_true",
                      help="simulator: the camera is triggered by the projector's VSYNC (the session's rig file says "
                           "capture.trigger 'projector'): no pattern delay, every frame's trigger count checked, a "
                           "missed trigger named and its view taken again")
    scan.add_argument("--frames", choices=("npy.zst", "png"), default=None,
                      help="the frame files of a new coded-light session: npy.zst (default: zstd-compressed NumPy "
                           "arrays, 3x faster to read than PNG and 4x to write, as many bytes; 'zstd -d' opens them) "
                           "or png")
    scan.add_argument("--sim-bump", type=_bump, metavar="VIEW:FRAME:MM",
                      help="simulator: knock the object MM along x from frame FRAME of view VIEW (from 0) to that "
                           "view's end; the scan finds the view moved and takes it again (the motion check)")
    _processing_options(scan)
    scan.set_defaults(func=cmd_scan)

    proc = sub.add_parser("process", help="decode, register and fuse an acquired session into a mesh",
                          formatter_class=LazyHelp,
                          description="Process a session folder (from 'rangekit scan'): every view decoded and "
                                      f"triangulated, registered from the turntable angles, fused into {MESH_FILE}. "
                                      "Several folders are processed on Dask: every view's decoding and then "
                                      "each session's registration and fusion are tasks of a local cluster or "
                                      "of a running 'dask scheduler' (--scheduler).")
    proc.add_argument("session", metavar="DIR", nargs="+",
                      help="session folder; several are processed on Dask (a view's decoding per task)")
    proc.add_argument("--scheduler", type=scheduler_address, metavar="local|ADDRESS",
                      help="Dask scheduler: 'local' (default with several sessions: a local cluster of --workers "
                           "processes) or the address tcp://HOST:PORT of a running 'dask scheduler' (docs/scale.md)")
    proc.add_argument("--workers", type=int_in(1, 256), metavar="N",
                      help="worker processes of --scheduler local, one thread each (default: RANGEKIT_WORKERS, else "
                           "the cores rangekit may use)")
    _processing_options(proc)
    proc.set_defaults(func=cmd_process)
