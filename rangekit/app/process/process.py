"""From an acquired session to one mesh: decode and triangulate every view, register the views seeded by
the turntable angles, fuse, measure against the truth when given an evaluator, report (the work behind
``rangekit process`` and the end of ``rangekit scan``). The pipeline is the same on hardware and on
the simulator: it never imports :mod:`rangekit.sim` (see :func:`rangekit.app.scan.truth.session_evaluator`).

Writes into the session folder (atomically):

    view_NNN/cloud.ply, maps.npz, cloud.json   each view's cloud, its decoded maps and depth (cache,
                                               rangekit.app.process.view_cache)
    poses.json                                 registered poses, world = the first view's frame
    merged.ply                                 all views in one frame
    mesh.ply, mesh_watertight.ply              the fused surface the views observed (open), and closed with
                                               a per-vertex ``observed`` flag (rangekit.app.process.fused_outputs)
    summary.json                               what the end-of-run summary prints, as data
    report.html                                the visual report (rangekit.app.report.page)

A view's cloud is reused when ``cloud.json`` says it was made with the same settings, so processing
that was interrupted (or rerun with another fusion method) does not decode again, and gives the same
mesh as an uninterrupted run.

The outputs are written as a set: a stale ``summary.json`` is removed first and the new one written
last, so a folder with ``summary.json`` always has the mesh, poses and merged cloud of the same run.
The stages (decode, register, fuse, evaluate, report) are pure steps; this module is their plan, run by the job
runner (:mod:`rangekit.app.runner`): it times and announces each stage, places each piece of work (a thread, a
child process, Dask: :data:`rangekit.app.runner.PLACEMENTS`) and takes what was done ahead from its memo.

Processing holds the session's lock and checks every view's frames against their recorded SHA-256s, taken
from the bytes it reads to decode them (:mod:`rangekit.formats.sessions.check`). Nothing it writes is read
back in the same run.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path

from rangekit._runtime.child import spawn_child
from rangekit._runtime.executor import Where, worker_count
from rangekit._runtime.threads import one_blas_thread
from rangekit.app.events import (MeshReady, OnEvent, PairRegistered, Stage, ViewDecoded, failures_announced)
from rangekit.app.process.decode import DecodedViews, decode
from rangekit.app.process.evaluate import Evaluator, measure_closed, measure_views
from rangekit.app.process.blocks import poisson_closed
from rangekit.app.process.fuse import (CHILD_IMPORTS, FusedViews, carved_space, close, fusion_input, large_poisson,
                                       observed_rule, save_closed, save_merged, save_observed, summary_line, surfaces)
from rangekit.app.process.fused_outputs import evaluate_observed
from rangekit.app.process.options import ProcessOptions
from rangekit.app.process.register import RegisteredViews, evaluator_angles, register
from rangekit.app.process.view_cache import cache_settings, table_transform, view_clouds
from rangekit.app.runner import Memo, Plan, Runner, Work
from rangekit.errors import ConfigError
from rangekit.formats.sessions.check import verify_views
from rangekit.formats.sessions.lock import session_lock
from rangekit.formats.sessions.session import Session
from rangekit.formats.sessions.summary import ProcessResult
from rangekit.io import atomic_write_json, fsync_folder
from rangekit.formats.sessions.files import MESH_FILE, REPORT_FILE, SESSION_FILE, SUMMARY_FILE, WATERTIGHT_FILE

__all__ = ["process_session"]


def process_session(session: Session | str | Path, options: ProcessOptions | None = None, *,
                    evaluate: Evaluator | None = None, on_event: OnEvent | None = None, plan: Plan = Plan.LOCAL,
                    memo: Memo | None = None) -> ProcessResult:
    """Process the completed views of a session (a loaded :class:`Session` or its folder) into ``mesh.ply``
    (the observed surface) and ``mesh_watertight.ply`` (closed, flagged; and ``summary.json``, ``report.html``).

    Parameters
    ----------
    options : how (:class:`ProcessOptions`: fusion, triangulation, table margin, report); the defaults if None.
    evaluate : measures the mesh against the truth (:data:`rangekit.app.process.evaluate.Evaluator`); None on
        hardware. Processing itself never imports the simulator.
    on_event : given every event (:mod:`rangekit.app.events`) on the job's event bus: stages, progress lines,
        each view's cloud as it is decoded (before the fusion starts), each registered pair, each mesh written; an
        error as :class:`JobFailed` before it is raised.
    plan : where the work runs (:class:`rangekit.app.runner.Plan`: one process, a scan's, a Dask task's).
    memo : what was done ahead (:class:`rangekit.app.runner.Memo`: a scan's views decoded as they came, its
        registration's first pairs, its prepared evaluator), taken where it is exactly what the stages compute:
        the outputs are the same bytes with or without it.

    Raises
    ------
    FileFormatError
        A view's frames differ from the SHA-256s recorded in session.json (changed, missing, extra).
    SessionLocked
        Another process is working on the session.
    """
    options = options or ProcessOptions()
    folder = Path(session.folder if isinstance(session, Session) else session)
    runner = Runner(on_event, plan=plan, memo=memo)
    try:
        with failures_announced(runner.emit):
            if not (folder / SESSION_FILE).is_file():
                raise ConfigError(f"{folder}: not a session folder (no {SESSION_FILE})")
        with failures_announced(runner.emit), session_lock(folder), one_blas_thread(), ExitStack() as children:
            if not isinstance(session, Session):    # (one BLAS thread: thin products, rangekit._runtime.threads)
                session = Session.load(folder)
            return _process(session, options, evaluate, runner, children)
    finally:
        runner.close()


def _process(session: Session, options: ProcessOptions, evaluate: Evaluator | None, runner: Runner,
             children: ExitStack) -> ProcessResult:
    """The stages in order: check the session, decode (with the report's per-view part), register, fuse (the
    views measured beside it), measure, report, and summary.json last."""
    _start(session, runner)
    if session.is_laser:
        from rangekit.app.process.laser import process_laser

        return process_laser(session, options, evaluate, runner)
    with runner.stage(Stage.DECODE, reuse_memory=True):   # each view's stacks reuse the last one's pages
        decoded = decode(session, options, _decoded_views(session, options, runner), runner.memo.free)
    # the Poisson child imports on the other core while the views register
    child = spawn_child(CHILD_IMPORTS) if large_poisson(decoded, options) and \
        runner.where(Work.POISSON) is Where.CHILD else None
    if child is not None:
        children.enter_context(child)    # ended if anything below fails
    angles = evaluator_angles(decoded.views, multi_pass=session.plan.passes > 1)
    with (runner.beside(Work.TRUTH_PREPARE, evaluate.prepare, angles) if evaluate is not None else
          runner.beside(Work.TRUTH_PREPARE, _nothing, where=Where.HERE)) as truth:
        with runner.stage(Stage.REGISTER, release_after=True):   # the registration's k-d trees and samples
            registered = register(decoded, session, progress=runner.progress, map_pairs=runner.pair_mapper(),
                                  ahead=runner.memo.registration)
            for e in registered.edges:
                runner.emit(PairRegistered(e.i, e.j, e.rmse, e.overlap, e.accepted, e.reason))
        truth.result()
    agreement = []     # the report's views' agreement, started as soon as the observed mesh is made
    with runner.stage(Stage.FUSE):
        fused = _fuse(registered, session, options, evaluate, child, runner, agreement, children)
    accuracy = truth_mesh = view_errors = None
    if evaluate is not None:
        with runner.stage(Stage.EVALUATE):
            runner.say("measuring the closed mesh against the true surface")
            accuracy, truth_mesh, view_errors = measure_closed(evaluate, fused, registered)
    # Stage times are wall seconds; "evaluate" includes the part done beside the fusion (inside "fuse").
    result = ProcessResult(session.folder, decoded.names, registered.T_world_view, [len(c) for c in decoded.clouds],
                           registered.edges, registered.rmse, fused.observed_info, runner.seconds, accuracy,
                           watertight_mesh=fused.watertight_info, view_errors=view_errors,
                           view_passes=registered.view_passes, registration_note=registered.note,
                           options=options.to_dict())
    if options.report:
        _report(result, registered, fused, session, truth_mesh, runner, agreement[0].result())
    atomic_write_json(session.folder / SUMMARY_FILE, result.to_dict())   # last: the set is complete
    return result


def _nothing(*_args) -> None:
    return None


def _decoded_views(session: Session, options: ProcessOptions, runner: Runner) -> Iterator:
    """Each completed view's ``(cloud, ViewMaps)`` in order, for the decode stage: taken from the memo (decoded
    ahead, its frames checked then; taken out as it is used, so its maps are freed with the others') or decoded
    on the runner's worker threads, the next view's frames read while one decodes, each frame once (its SHA-256
    checked from the bytes read). Each view is announced as :class:`ViewDecoded` (a view from the memo was, when
    it was decoded, unless the memo says otherwise: Dask's view tasks announce nothing) and as a progress line."""
    views, given, announced = session.done_views, runner.memo.decoded, runner.memo.announced
    settings = cache_settings(session, options.method, options.table_margin, options.max_motion)
    handed = {v.index for v in views if v.index in given}
    rest = view_clouds([v for v in views if v.index not in handed], session.pattern, session.rig, settings,
                       session.capture.full_scale, table_transform(session.rig), options.table_margin, session,
                       map_views=runner.map_views)
    for k, v in enumerate(views):
        cloud, maps = given.pop(v.index) if v.index in handed else next(rest)
        if v.index not in handed or not announced:
            runner.emit(ViewDecoded(k, len(views), v.folder.name, cloud))
        runner.say(f"decoded {v.folder.name}: {len(cloud):,} points", k + 1, len(views))
        yield cloud, maps
        del cloud, maps


def _fuse(registered: RegisteredViews, session: Session, options: ProcessOptions, evaluate: Evaluator | None,
          child, runner: Runner, agreement: list, children: ExitStack) -> FusedViews:
    """The fuse stage's steps, placed: the fusion beside this thread (a child for a large Poisson, else a
    thread) while the merged cloud is written and the views are measured; then the observed mesh cut and saved,
    and measured, while the rest is closed on a thread; the report's views' agreement started on a thread as soon
    as the observed mesh is saved. A scan's measures against the truth (``Memo.truth_after_mesh``) come once both
    meshes are written, beside nothing that makes them: the mesh a person waits for comes first, and no
    simulator-only work (its reuse of freed memory, its threads) runs beside the closing."""
    out = session.folder
    given = fusion_input(registered, options)
    late = evaluate is not None and runner.memo.truth_after_mesh   # a scan: the views measured after mesh.ply
    runner.say(f"fusing {given.n_merged:,} points ({options.fusion})"
               + ("; measuring the views against the true surface alongside" if evaluate is not None and not late
                  else ""))
    blocks = options.fusion == "blocks"   # its closed mesh is Poisson's (blocks.poisson_closed): the child is that's
    # a scan's blocks: the observed rule (its k-d tree) first, while its volume makes the surface in its own child
    rule = observed_rule(given, options) if blocks and runner.memo.blocks is not None else None
    if blocks and runner.memo.blocks is not None and runner.memo.before_mesh is not None:
        runner.memo.before_mesh()   # a scan's preview, then its volume finished on the same thread (BlocksAhead)
    fn, args, kwargs = surfaces(given if options.fusion == "poisson" else registered, options, session.rig,
                                passes=session.plan.passes, ahead=runner.memo.blocks)
    work = Work.POISSON if options.fusion == "poisson" else Work.TSDF
    where = runner.where(work) if options.fusion != "poisson" or large_poisson(registered.decoded, options) \
        else Where.THREAD
    with runner.beside(work, fn, *args, where=where, child=None if blocks else child, **kwargs) as fusion:
        if not blocks:   # blocks: merged.ply once mesh.ply is out (the blocks' surface was made ahead in a scan)
            save_merged(out, given, registered)
        runner.release_memory()   # the input's copy sent to the fusion's child, the merged file's: before the casts
        if evaluate is not None and not late:
            with runner.stage(Stage.EVALUATE, reuse_memory=True):   # each view's casts reuse the last's pages
                measure_views(evaluate, registered)
        elif not late:
            measure_views(None, registered)
        runner.release_memory()
        rule = rule if rule is not None else observed_rule(given, options)
        sample = given.sample   # (the blocks fusion's closed mesh's input; None otherwise)
        runner.release_memory()   # what this process freed beside Poisson, before the closing and the evaluation
        full, trimmed = fusion.result()
        evaluation = None
        # blocks: mesh.ply before its closed mesh's Poisson starts on the other core (a scan's query uses both)
        early = save_observed(out, full, rule, options, worker_count()) if blocks else None
        with _closing(runner, trimmed, sample, options, child, registered) as closing:
            del trimmed, sample
            mesh, mesh_info = early if early is not None else save_observed(out, full, rule, options)
            del full, early
            if runner.memo.before_mesh is not None:   # a scan's preview: announced first (Memo)
                runner.memo.before_mesh()
            runner.emit(MeshReady("observed", out / MESH_FILE, mesh))
            if blocks:
                save_merged(out, given, registered)
            del given
            agreement.append(children.enter_context(_agreement_beside(options.report, mesh, registered, runner)))
            if evaluate is not None and not late:
                evaluation = _measure_observed(evaluate, mesh, registered, runner)
            space = carved_space(registered, mesh, session.rig)
            closed = closing.result()
        runner.release_memory()   # the fusion's and the evaluator's temporaries
        watertight, watertight_info = save_closed(out, closed, rule, options, space)
        del space
        del closed, rule
        runner.emit(MeshReady("watertight", out / WATERTIGHT_FILE, watertight))
        runner.say(summary_line(mesh, watertight_info))
    if late:   # the views and the observed mesh against the truth once both meshes are out (Memo.truth_after_mesh)
        with runner.stage(Stage.EVALUATE, reuse_memory=True):
            measure_views(evaluate, registered)
        evaluation = _measure_observed(evaluate, mesh, registered, runner)
    return FusedViews(mesh, watertight, mesh_info, watertight_info, evaluation)


def _closing(runner: Runner, trimmed, sample, options: ProcessOptions, child, registered: RegisteredViews):
    """The surface to close closed beside this thread (:func:`close`, on a thread); the blocks fusion's closed mesh
    from the sample by Poisson instead (:func:`poisson_closed`, in the child spawned for it when large), as
    ``with ... as call: ...; call.result()``."""
    if options.fusion != "blocks":
        return runner.beside(Work.CLOSING, close, trimmed)
    where = runner.where(Work.POISSON) if large_poisson(registered.decoded, options) else Where.THREAD
    return runner.beside(Work.POISSON, poisson_closed, sample, options.poisson(laser=False)[0], where=where,
                         child=child)


def _measure_observed(evaluate: Evaluator, mesh, registered: RegisteredViews, runner: Runner):
    """The observed mesh and each view against the true surface (:func:`evaluate_observed`), as a stage."""
    with runner.stage(Stage.EVALUATE):
        runner.say("measuring the observed mesh and each view against the true surface")
        return evaluate_observed(evaluate, mesh, registered.angles, views=registered)


def _start(session: Session, runner: Runner) -> None:
    """Check the session before any work: at least two completed views, each with its recorded frames and no
    others (their contents are checked as they are read for decoding); then remove a stale summary.json, so
    that the outputs are a set (it comes back last)."""
    out = session.folder
    if len(session.done_views) < 2:
        raise ConfigError(f"{out}: {len(session.done_views)} completed view(s); processing needs at least 2 "
                          "(resume the scan)")
    unverified = verify_views(session, contents=False)
    if unverified:
        runner.say(f"{', '.join(unverified)}: no frame checksums in {SESSION_FILE} (written by an older rangekit); "
                   "their frames are not verified")
    stale = out / SUMMARY_FILE
    if stale.exists():
        stale.unlink()
        fsync_folder(out)


def _agreement_beside(report: bool, observed, registered: RegisteredViews, runner: Runner):
    """The report's views' agreement (:func:`rangekit.app.report.context.views_agreement`) of the ``observed`` mesh
    and the registered clouds beside this thread, as ``with ... as call: ...; call.result()``; a call whose result
    is None without a report. Started as soon as the observed mesh is made, beside its evaluation and the closing
    of the mesh, it is done before the closed mesh's evaluation ends (it finished 0.5 s after it, started then)."""
    from rangekit.app.report.context import views_agreement

    if not report:
        return runner.beside(Work.AGREEMENT, _nothing)
    return runner.beside(Work.AGREEMENT, views_agreement, observed, registered.T_world_view, registered.clouds)


def _report(result: ProcessResult, registered: RegisteredViews, fused: FusedViews, session: Session, truth,
            runner: Runner, agreement: tuple | None) -> None:
    """``report.html``: the summary, the meshes, the per-view rows made as the views were decoded; its panels on
    the runner's worker threads."""
    import numpy as np

    from rangekit.app.report.page import write_report
    from rangekit.geometry import apply_T
    from rangekit.surface.cloud import PointCloud

    d = registered.decoded
    with runner.stage(Stage.REPORT):
        runner.say(f"writing {REPORT_FILE}")
        runner.release_memory()   # the evaluation's temporaries
        # The report draws the merged cloud's points only: not its normals, colours and sigma (2M points each)
        merged = PointCloud(np.concatenate([apply_T(T, c.points) for T, c in zip(registered.T_world_view, d.clouds)]))
        write_report(session.folder, result, clouds=d.clouds, maps=None, rows=d.rows,
                     merged=merged, mesh=fused.observed, session=session,
                     truth=truth, progress=runner.progress, watertight=fused.watertight, agreement=agreement,
                     map_panels=runner.map_ordered)
