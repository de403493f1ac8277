"""``rangekit scan`` and ``rangekit process``: a turntable session, acquired (resumable) and processed."""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from rangekit.cli._common import (LazyChoices, check_output, console, finite_float, note, result, int_in, say, scheduler_address,
                                  seed)
from rangekit.errors import UsageError


def cmd_scan(args: argparse.Namespace) -> int:
    """rangekit scan --out DIR | --resume DIR [--method coded|laser] [--rig sim|RIG.json] [--object lumpy]
    [--views 12 | --steps 400] [--passes 2 [--flipped]] [--patterns hybrid] [--up X Y Z] [--allow-auto-exposure]"""
    from rangekit.formats.sessions.lock import session_lock as session_lock_of

    t0 = time.perf_counter()
    if args.artefact:
        return _scan_artefacts(args, t0)
    if args.positions is not None:
        raise UsageError("--positions: artefact positions of --artefact vdi2634; give --artefact vdi2634 or leave it out")
    check_output(args.out or args.resume, option="--out" if args.out else "--resume", folder=True,
                 session=bool(args.resume))
    if args.resume and Path(args.resume, "session.json").is_file():
        # Held from the first read of the session to the end of processing (acquire and process take it
        # again, re-entrantly): a second scan or process of this folder stops at once.
        with session_lock_of(args.resume):
            return _scan(args, t0)
    return _scan(args, t0)


#: Options of a turntable scan that --artefact (one view per artefact position, coded light) does not take.
_NOT_WITH_ARTEFACT = {"resume": "--resume", "method": "--method", "steps": "--steps", "up": "--up", "object": "--object",
                      "views": "--views", "patterns": "--patterns", "no_process": "--no-process", "passes": "--passes",
                      "flipped": "--flipped"}


def _scan_artefacts(args: argparse.Namespace, t0: float) -> int:
    """rangekit scan --artefact vdi2634 --out DIR [--rig RIG.json] [--positions S B P] [--seed N]"""
    from rangekit.app.scan.vdi2634 import figure_lines, run_vdi2634
    from rangekit.sim.scene.artefacts import GUIDELINE_POSITIONS

    given = [opt for key, opt in _NOT_WITH_ARTEFACT.items() if getattr(args, key, None) not in (None, False)]
    if given:
        raise UsageError(f"{', '.join(given)}: not used by --artefact {args.artefact} (one single-view coded-light "
                         "capture per artefact position on the simulator); leave them out")
    if not args.out:
        raise UsageError(f"--artefact {args.artefact}: expected --out DIR, found none")
    check_output(args.out, option="--out", folder=True)
    counts = tuple(args.positions) if args.positions is not None else GUIDELINE_POSITIONS
    for n, most, what in zip(counts, GUIDELINE_POSITIONS, ("sphere", "ball bar", "plane")):
        if not 0 <= n <= most:
            raise UsageError(f"--positions: {what} positions must be in 0..{most}, found {n}")
    if not any(counts):
        raise UsageError(f"--positions: expected at least one artefact position, found {' '.join(map(str, counts))}")
    rig = None if args.rig in (None, "sim") else args.rig
    if rig is not None and not Path(rig).is_file():
        raise UsageError(f"--rig {rig}: expected a rig file from 'rangekit calibrate', found "
                         f"{'a folder' if Path(rig).is_dir() else 'no such file'}")
    res = run_vdi2634(args.out, rig_file=rig, n_spheres=counts[0], n_bars=counts[1], n_planes=counts[2],
                      seed=0 if args.seed is None else args.seed, progress=console())
    say("")
    for line in figure_lines(res):
        say(line)
    result(f"wrote {args.out}/vdi2634.json in {time.perf_counter() - t0:.1f} s")
    return 0


def _scan(args: argparse.Namespace, t0: float) -> int:
    from rangekit.app.acquire.acquire import acquire
    from rangekit.app.scan.scan import prepare_scan
    from rangekit.formats.sessions.session import ScanPlan

    if args.steps is not None and args.views is not None:
        raise UsageError("--steps and --views both give the turntable positions; give one (--steps for a laser scan)")
    if args.method != "laser" and args.steps is not None and not args.resume:
        raise UsageError("--steps: turntable steps of a laser scan; with --method coded give --views")
    if args.flipped and not args.resume:
        raise UsageError("--flipped confirms, when resuming a multi-pass scan, that the object was turned over; "
                         "give it with --resume DIR")
    setup = prepare_scan(out=args.out, resume=args.resume, rig=args.rig, obj=args.object,
                         n_views=args.views if args.steps is None else args.steps, patterns=args.patterns,
                         seed=args.seed, fusion=args.fusion, method=args.method, up=args.up, progress=console(),
                         passes=args.passes)
    folder = args.resume or args.out
    if args.exposures is not None:
        setup = _with_exposures(setup, args.exposures)
    if setup.resume:
        note(f"resuming {folder}: {setup.n_done}/{setup.n_views} views already done")
    try:
        turn_over = None
        if setup.hardware is not None and setup.passes > 1:   # the simulator turns its object over itself
            from rangekit.app.scan.passes import turn_over_prompt

            turn_over = turn_over_prompt(folder, setup.passes, flipped=args.flipped)
        session = acquire(setup.devices, setup.rig, setup.spec, folder,
                          plan=ScanPlan(n_views=setup.n_views, passes=setup.passes),
                          resume=setup.resume, capture=setup.capture, simulator=setup.simulator,
                          hardware=setup.hardware, files=setup.files, progress=console(),
                          allow_auto_exposure=args.allow_auto_exposure, turn_over=turn_over)
    except KeyboardInterrupt:
        print(f"rangekit: interrupted; completed views are safe. Continue with: rangekit scan --resume {folder}",
              file=sys.stderr)
        return 130
    finally:
        setup.close()
    (say if not args.no_process else result)(f"acquired {len(session.done_views)} {'steps' if session.is_laser else 'views'} x {setup.spec.n_frames} "
        f"frames into {folder} in "
        f"{time.perf_counter() - t0:.1f} s")
    if args.no_process:
        say(f"process it later with: rangekit process {folder}")
        return 0
    t_acq = time.perf_counter() - t0
    return _process(folder, args, acquisition_s=t_acq, resume_cmd=f"rangekit scan --resume {folder}")


def _exposures(text: str):
    """Argument type of --exposures: 'auto' or microseconds 1..1000000."""
    return text if text == "auto" else int_in(1, 1_000_000)(text)


def _with_exposures(setup, given: list):
    """The scan set-up with ``--exposures`` (a new coded-light scan only): the exposures given, increasing,
    or with 'auto' those of rangekit check's statistics on the devices."""
    from dataclasses import replace

    from rangekit.app.check.steps import exposures_from_check
    from rangekit.rig.camera_controls import controls_from_capture

    if setup.resume:
        setup.close()
        raise UsageError("--exposures: a resumed scan keeps its session's exposures; leave --exposures out")
    from rangekit.laser.sequence import LaserSequence

    if isinstance(setup.spec, LaserSequence):
        setup.close()
        raise UsageError("--exposures: multi-exposure capture is for coded light; leave it out with --method laser")
    if "auto" in given:
        if len(given) != 1:
            setup.close()
            raise UsageError(f"--exposures: expected 'auto' alone or 2 to 8 exposures in microseconds, found "
                             f"{' '.join(map(str, given))}")
        full_scale = setup.capture.full_scale or 255.0
        exps = exposures_from_check(setup.devices, setup.rig, controls_from_capture(setup.rig.capture, where="rig file"),
                                    full_scale)
        say(f"--exposures auto: {' '.join(map(str, exps))} us (from rangekit check's statistics)")
    else:
        exps = tuple(sorted(set(given)))
    if not 2 <= len(exps) <= 8:
        setup.close()
        raise UsageError(f"--exposures: expected 2 to 8 different exposures, found {' '.join(map(str, given))}")
    return replace(setup, capture=replace(setup.capture, exposures_us=tuple(int(e) for e in exps)))


def _process(folder: str, args: argparse.Namespace, *, acquisition_s: float | None = None,
             resume_cmd: str | None = None) -> int:
    from rangekit.app.process.fused_outputs import export_meshes
    from rangekit.app.scan.scan import process_scan
    from rangekit.progress import format_seconds

    t0 = time.perf_counter()
    try:
        res = process_scan(folder, fusion=args.fusion, report=not args.no_report, progress=console())
    except KeyboardInterrupt:
        print(f"rangekit: interrupted; the views decoded so far are cached. Continue with: "
              f"{resume_cmd or f'rangekit process {folder}'}", file=sys.stderr)
        return 130
    say("")
    say(f"== {folder}: summary ==")
    if acquisition_s is not None:
        say(f"acquisition: {format_seconds(acquisition_s)}")
    for line in res.summary_lines():
        say(line)
    total = time.perf_counter() - t0 + (acquisition_s or 0.0)
    exported = export_meshes(Path(folder), args.format)
    result(f"wrote {folder}/mesh.ply (observed surface), mesh_watertight.ply (closed), "
        + "".join(f"{name}, " for name in exported) + "merged.ply, poses.json, summary.json"
        + ("" if args.no_report else ", report.html") + f" in {format_seconds(total)}")
    return 0


def cmd_process(args: argparse.Namespace) -> int:
    """rangekit process DIR [DIR ...] [--fusion poisson|tsdf] [--scheduler local|ADDRESS] [--workers N]: decode,
    register and fuse each session into DIR/mesh.ply; several sessions (or --scheduler) on Dask"""
    if len(args.session) == 1 and args.scheduler is None:
        if args.workers is not None:
            raise UsageError(f"--workers: Dask workers for several sessions or --scheduler; found {args.workers} "
                             "with one session and no --scheduler (give --scheduler local, or leave --workers out)")
        check_output(args.session[0], option="DIR", folder=True, session=True)
        return _process(args.session[0], args)
    return _process_batch(args)


def _process_batch(args: argparse.Namespace) -> int:
    """Several sessions on Dask (rangekit.app.process.batch): a line per view and session, then each session done or
    failed; exit 1 when any failed."""
    from rangekit.app.process.batch import process_sessions
    from rangekit.app.process.fused_outputs import export_meshes
    from rangekit.progress import format_seconds

    scheduler = args.scheduler or "local"
    if scheduler != "local" and args.workers is not None:
        raise UsageError(f"--workers: the number of workers of --scheduler local; the scheduler at {scheduler} has "
                         f"its own workers, found --workers {args.workers}; leave it out")
    if len(set(Path(s).resolve() for s in args.session)) != len(args.session):
        raise UsageError(f"DIR: expected different session folders, found one given twice in {' '.join(args.session)}")
    for s in args.session:
        check_output(s, option="DIR", folder=True)
    where = f"a local cluster of {args.workers or 2} worker processes" if scheduler == "local" else scheduler
    note(f"processing {len(args.session)} session(s) on {where}")
    try:
        res = process_sessions(args.session, scheduler=scheduler, workers=args.workers or 2, fusion=args.fusion,
                               report=not args.no_report, progress=console())
    except KeyboardInterrupt:
        print(f"rangekit: interrupted; the views decoded so far are cached. Continue with: rangekit process "
              f"{' '.join(args.session)}", file=sys.stderr)
        return 130
    say("")
    result(f"== {len(res.sessions) - len(res.failed)} of {len(res.sessions)} session(s) processed in "
        f"{format_seconds(res.seconds)} ==")
    for o in res.sessions:
        if o.ok:
            export_meshes(Path(o.folder), args.format)
            say(f"{o.folder}: done ({o.views_decoded} views decoded, {o.views_cached} from the cache); "
                + (o.summary[0] if o.summary else ""))
        else:
            result(f"{o.folder}: FAILED: {o.error}")
    return 1 if res.failed else 0


def _processing_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--fusion", default="poisson", choices=LazyChoices("rangekit.app.process.options", "FUSION_METHODS"),
                   metavar="{poisson,tsdf}",
                   help="fusion into one mesh: poisson (default, screened Poisson of the merged cloud) or tsdf")
    p.add_argument("--no-report", action="store_true", help="skip report.html")
    p.add_argument("--format", default="ply", choices=LazyChoices("rangekit.app.process.fused_outputs", "MESH_EXPORT_FORMATS"),
                   metavar="{ply,obj,stl,glb}",
                   help="mesh files: ply (default; mesh.ply and mesh_watertight.ply, with vertex normals and the "
                        "'observed' flag) or obj, stl, glb written beside them as mesh.FMT and mesh_watertight.FMT")


def add_parsers(sub) -> None:
    from rangekit.coded.patterns import PATTERN_METHODS

    scan = sub.add_parser("scan", help="scan: acquire a turntable session (resumable), then process it into a mesh",
                          description="Acquire a crash-safe scan session (every turntable view, every pattern; "
                                      "--resume continues an interrupted one without redoing finished views), then "
                                      "decode, register and fuse it into DIR/mesh.ply.")
    where = scan.add_mutually_exclusive_group(required=True)  # --artefact takes --out
    where.add_argument("--out", help="new session folder")
    where.add_argument("--resume", metavar="DIR", help="continue the session in DIR")
    # No argparse defaults: a resumed scan takes the session's settings, and an option given with --resume
    # must equal them (rangekit.app.scan.scan.SCAN_DEFAULTS fills in a new scan).
    scan.add_argument("--method", choices=("coded", "laser"),
                      help="coded (default: projector patterns, views registered) or laser (the rig's line lasers, "
                           "switched by the turntable board, one profile per turntable step)")
    scan.add_argument("--steps", type=int_in(2, 3600), help="turntable steps over a full turn of a laser scan "
                                                            "(default 400)")
    scan.add_argument("--up", type=finite_float, nargs=3, metavar=("X", "Y", "Z"),
                      help="a mesh file object's up direction, stood upright on the turntable (Stanford scans: 0 1 0)")
    scan.add_argument("--rig", help="'sim' (default) or a rig file whose 'devices' name the turntable, projector and "
                                    "camera")
    scan.add_argument("--object", help="simulated object: built-in name (default lumpy) or mesh file (copied into "
                                       "the session)")
    scan.add_argument("--views", type=int_in(2, 720), help="turntable views over a full turn (default 12)")
    scan.add_argument("--passes", type=int_in(1, 8),
                      help="turntable passes of --views views each, the object turned over between them to see its "
                           "bottom (default 1; the simulator turns it over itself, a real rig asks)")
    scan.add_argument("--flipped", action="store_true",
                      help="with --resume: the object has been turned over for the next pass (no terminal to ask on)")
    scan.add_argument("--patterns", choices=PATTERN_METHODS, help="pattern set (default hybrid: Gray code + phase "
                                                                  "shift)")
    scan.add_argument("--seed", type=seed, help="simulator noise seed (default 0)")
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
    _processing_options(scan)
    scan.set_defaults(func=cmd_scan)

    proc = sub.add_parser("process", help="decode, register and fuse an acquired session into a mesh",
                          description="Process a session folder (from 'rangekit scan'): every view decoded and "
                                      "triangulated, registered from the turntable angles, fused into mesh.ply. "
                                      "Several folders are processed on Dask: every view's decoding and then "
                                      "each session's registration and fusion are tasks of a local cluster or "
                                      "of a running 'dask scheduler' (--scheduler).")
    proc.add_argument("session", metavar="DIR", nargs="+",
                      help="session folder; several are processed on Dask (a view's decoding per task)")
    proc.add_argument("--scheduler", type=scheduler_address, metavar="local|ADDRESS",
                      help="Dask scheduler: 'local' (default with several sessions: a local cluster of --workers "
                           "processes) or the address tcp://HOST:PORT of a running 'dask scheduler' (docs/scale.md)")
    proc.add_argument("--workers", type=int_in(1, 256), metavar="N",
                      help="worker processes of --scheduler local, one thread each (default 2)")
    _processing_options(proc)
    proc.set_defaults(func=cmd_process)
