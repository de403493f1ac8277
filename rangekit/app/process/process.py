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
Processing holds the session's lock and checks every view's frames against their recorded SHA-256s, taken
from the bytes it reads to decode them (:mod:`rangekit.formats.sessions.check`). Nothing it writes is read
back in the same run.
"""

from __future__ import annotations

from contextlib import ExitStack
from pathlib import Path
from typing import TYPE_CHECKING

from rangekit._runtime.child import call_beside
from rangekit._runtime.memory import release_free_memory
from rangekit._runtime.threads import one_blas_thread
from rangekit.app.events import OnEvent, StageClock, failures_announced, progress_of
from rangekit.app.process.decode import decode
from rangekit.app.process.evaluate import Evaluator, measure_closed, measure_views, prepared_beside
from rangekit.app.process.fuse import Fusion, poisson_child
from rangekit.app.process.options import ProcessOptions
from rangekit.app.process.register import evaluator_angles, register
from rangekit.errors import ConfigError
from rangekit.formats.sessions.check import verify_views
from rangekit.formats.sessions.lock import session_lock
from rangekit.formats.sessions.session import Session
from rangekit.formats.sessions.summary import ProcessResult
from rangekit.io import atomic_write_json, fsync_folder
from rangekit.progress import call_progress

if TYPE_CHECKING:
    from rangekit.registration.ahead import RegistrationAhead
    from rangekit.registration.pair_refine import PairMapper

__all__ = ["process_session"]


def process_session(session: Session | str | Path, options: ProcessOptions | None = None, *,
                    evaluate: Evaluator | None = None, on_event: OnEvent | None = None,
                    map_pairs: PairMapper | None = None, decoded_views: dict | None = None,
                    registration_ahead: RegistrationAhead | None = None) -> ProcessResult:
    """Process the completed views of a session (a loaded :class:`Session` or its folder) into ``mesh.ply``
    (the observed surface) and ``mesh_watertight.ply`` (closed, flagged; and ``summary.json``, ``report.html``).

    Parameters
    ----------
    options : how (:class:`ProcessOptions`: fusion, triangulation, table margin, report); the defaults if None.
    evaluate : measures the mesh against the truth (:data:`rangekit.app.process.evaluate.Evaluator`); None on
        hardware. Processing itself never imports the simulator.
    on_event : given every event (:mod:`rangekit.app.events`): stages, progress lines, each view's cloud as it
        is decoded (before the fusion starts), each registered pair, each mesh written; an error as
        :class:`JobFailed` before it is raised.
    map_pairs : runs the registration's pair refinements (:func:`rangekit.registration.multiview.register_views`;
        the Dask batch maps them onto its workers); None: here, one after another.
    decoded_views : views already decoded in this run, by index: ``(cloud, ViewMaps)`` as
        :func:`rangekit.app.process.view_cache.view_cloud` gives them, their frames checked when they were read
        (the scan's streaming processor, :mod:`rangekit.app.scan.streaming`); the others are decoded or read
        from their cache.
    registration_ahead : what the scan's streaming processor registered as the views came
        (:class:`rangekit.registration.ahead.RegistrationAhead`): taken where it is exactly what the register stage
        computes, so the outputs are the same bytes with or without it.

    Raises
    ------
    FileFormatError
        A view's frames differ from the SHA-256s recorded in session.json (changed, missing, extra).
    SessionLocked
        Another process is working on the session.
    """
    options = options or ProcessOptions()
    folder = Path(session.folder if isinstance(session, Session) else session)
    with failures_announced(on_event):
        if not (folder / "session.json").is_file():
            raise ConfigError(f"{folder}: not a session folder (no session.json)")
    with failures_announced(on_event), session_lock(folder), one_blas_thread(), ExitStack() as children:
        if not isinstance(session, Session):    # (one BLAS thread: thin products, rangekit._runtime.threads)
            session = Session.load(folder)
        return _process(session, options, evaluate, on_event, map_pairs, children, decoded_views or {},
                        registration_ahead)


def _process(session: Session, options: ProcessOptions, evaluate: Evaluator | None, on_event: OnEvent | None,
             map_pairs: PairMapper | None, children: ExitStack, decoded_views: dict,
             registration_ahead: RegistrationAhead | None) -> ProcessResult:
    """The stages in order: check the session, decode (with the report's per-view part), register, fuse (the
    views measured beside it), measure, report, and summary.json last."""
    _start(session, on_event)
    if session.is_laser:
        from rangekit.app.laser.process import process_laser

        return process_laser(session, options, evaluate, on_event)
    clock = StageClock(on_event)
    decoded = decode(session, options, clock, on_event, given=decoded_views)
    child = poisson_child(decoded, options, children)      # imports on the other core while the views register
    measuring = evaluate is not None
    with prepared_beside(evaluate, evaluator_angles(decoded.views, multi_pass=session.plan.passes > 1)):
        registered = register(decoded, session, clock, on_event, map_pairs=map_pairs, ahead=registration_ahead)
    agreement = []     # the report's views' agreement, started as soon as the observed mesh is made

    def start_agreement(observed) -> None:
        agreement.append(children.enter_context(_agreement_beside(options.report, observed, registered)))

    with clock.stage("fuse"), Fusion(registered, session, options, child, on_event,
                                     measuring_beside=measuring) as fusion:
        fusion.save_merged()
        measure_views(evaluate, registered, clock)          # beside the fusion
        release_free_memory()
        fused = fusion.meshes(clock, evaluate, beside_observed=start_agreement)
    accuracy, truth, view_errors = (measure_closed(evaluate, fused, registered, clock, on_event)
                                    if evaluate is not None else (None, None, None))
    # Stage times are wall seconds; "evaluate" includes the part done beside the fusion (inside "fuse").
    result = ProcessResult(session.folder, decoded.names, registered.T_world_view, [len(c) for c in decoded.clouds],
                           registered.edges, registered.rmse, fused.observed_info, clock.seconds, accuracy,
                           watertight_mesh=fused.watertight_info, view_errors=view_errors,
                           view_passes=registered.view_passes, registration_note=registered.note,
                           options=options.to_dict())
    if options.report:
        _report(result, registered, fused, session, truth, clock, on_event, agreement[0].result())
    atomic_write_json(session.folder / "summary.json", result.to_dict())   # last: the set is complete
    return result


def _start(session: Session, on_event: OnEvent | None) -> None:
    """Check the session before any work: at least two completed views, each with its recorded frames and no
    others (their contents are checked as they are read for decoding); then remove a stale summary.json, so
    that the outputs are a set (it comes back last)."""
    out = session.folder
    if len(session.done_views) < 2:
        raise ConfigError(f"{out}: {len(session.done_views)} completed view(s); processing needs at least 2 "
                          "(resume the scan)")
    unverified = verify_views(session, contents=False)
    if unverified:
        call_progress(progress_of(on_event), f"{', '.join(unverified)}: no frame checksums in session.json "
                                             "(written by an older rangekit); their frames are not verified")
    stale = out / "summary.json"
    if stale.exists():
        stale.unlink()
        fsync_folder(out)


def _agreement_beside(report: bool, observed, registered):
    """The report's views' agreement (:func:`rangekit.app.report.context.views_agreement`) of the ``observed`` mesh
    and the registered clouds on a thread, as ``with ... as call: ...; call.result()``; a call whose result is
    None without a report. Started as soon as the observed mesh is made, beside its evaluation and the closing of
    the mesh, it is done before the closed mesh's evaluation ends (it finished 0.5 s after it, started then)."""
    from rangekit.app.report.context import views_agreement

    if not report:
        return call_beside(lambda: None, in_child=False)
    return call_beside(views_agreement, observed, registered.T_world_view, registered.clouds, in_child=False)


def _report(result: ProcessResult, registered, fused, session: Session, truth, clock: StageClock,
            on_event: OnEvent | None, agreement: tuple | None) -> None:
    """``report.html``: the summary, the meshes, the per-view rows made as the views were decoded."""
    from rangekit.app.report.page import write_report
    from rangekit.surface.cloud import merge_clouds

    d = registered.decoded
    with clock.stage("report"):
        call_progress(progress_of(on_event), "writing report.html")
        release_free_memory()   # the evaluation's temporaries
        write_report(session.folder, result, clouds=d.clouds, maps=None, rows=d.rows,
                     merged=merge_clouds(d.clouds, registered.T_world_view), mesh=fused.observed, session=session,
                     truth=truth, progress=progress_of(on_event), watertight=fused.watertight, agreement=agreement)
