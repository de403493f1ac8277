"""The main job as one call: :func:`scan` checks the options, opens the devices, acquires (resumable) and
processes with the simulator's truth when there is one; ``rangekit scan`` is this call and a printer.

Processing itself (:mod:`rangekit.app.process.process`) does not know about the simulator: this module, which
does, builds the evaluator from :mod:`rangekit.sim` and passes it in.
"""

from __future__ import annotations

import time
from contextlib import ExitStack
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from rangekit._runtime.arguments import check_callable, check_instance, check_path
from rangekit._runtime.executor import Where, start
from rangekit.app.bus import EventBus
from rangekit.app.event_log import logged
from rangekit.app.events import OnEvent, ScanStarted, Stage, StageClock, emit, failures_announced, progress_of
from rangekit.app.runner import Memo, Plan, StreamingWorker
from rangekit.app.process.evaluate import Evaluator, measuring
from rangekit.app.process.options import ProcessOptions
from rangekit.app.process.process import process_session
from rangekit.app.scan.options import ScanOptions
from rangekit.app.scan.truth import session_evaluator
from rangekit.errors import ConfigError
from rangekit.formats.sessions.session import ScanPlan, Session
from rangekit.formats.sessions.summary import ProcessResult
from rangekit.laser.sequence import LaserSequence
from rangekit.formats.sessions.files import SESSION_FILE

if TYPE_CHECKING:
    from rangekit.app.scan.vdi2634 import Vdi2634Result

__all__ = ["ScanResult", "scan", "session_evaluator", "process", "process_placed", "REMOVED_KEYWORDS"]


@dataclass(frozen=True, eq=False)
class ScanResult:
    """What :func:`scan` did.

    folder : the session folder.
    session : the session as on disk after acquisition (every view's state).
    acquisition_seconds : wall seconds from the call to the last view on disk (set-up included).
    processed : the processing's result; None with ``ScanOptions(process=False)``.
    seconds : wall seconds of the whole call.
    vdi2634 : with ``ScanOptions(artefact="vdi2634")`` the guideline's figures (then ``session`` and
        ``processed`` are None).
    """

    folder: Path
    session: Session | None
    acquisition_seconds: float
    processed: ProcessResult | None
    seconds: float
    vdi2634: Vdi2634Result | None = None


def scan(options: ScanOptions, on_event: OnEvent | None = None) -> ScanResult:
    """Scan as ``rangekit scan`` does: set up (:func:`rangekit.app.scan.setup.prepare_scan`: everything checked
    before anything moves), acquire every view not yet done, then (``options.process``) decode, register and
    fuse with :func:`process`. ``on_event`` is given every event (:mod:`rangekit.app.events`): the scan's
    :class:`ScanStarted`, each :class:`ViewAcquired` (from the frame writer's thread, one at a time), then the
    processing's stages, views, pairs and meshes. A resumed session's lock is held from its first read to the
    end of processing: a second scan or process of the folder stops at once. A view during which the object moved
    (found as it is decoded while the scan runs: :class:`rangekit.errors.MotionError`) is taken once more after the
    others; if it moved again, the processing refuses it, naming it.

    Raises
    ------
    OptionError
        A bad option, or one that differs from the resumed session's (the message names the field).
    ConfigError, DeviceError, StorageError, SessionLocked, TurnOverNeeded
        As :func:`rangekit.app.acquire.acquire.acquire` and :func:`process` raise them; completed views stay
        on disk and ``ScanOptions(resume=folder)`` continues.
    InputError
        ``options`` is not a :class:`ScanOptions` or ``on_event`` not a callable (before anything is done).
    """
    check_instance("options", options, ScanOptions, "a ScanOptions (rk.scan(rk.ScanOptions(out=FOLDER)))")
    check_callable("on_event", on_event)
    on_event = logged(options.folder, on_event)     # events.jsonl in the session folder (rangekit.app.event_log)

    t0 = time.perf_counter()
    with EventBus(on_event) as bus:   # every subscriber on the bus's thread, never the capture's
        return _scan(options, bus, t0)


def _scan(options: ScanOptions, bus: EventBus, t0: float) -> ScanResult:
    """:func:`scan` with its event bus (:class:`rangekit.app.bus.EventBus`): the streaming worker's subscriber
    first (:class:`rangekit.app.runner.StreamingWorker`: it queues the views as they are acquired), then the
    caller's."""
    from rangekit.formats.sessions.lock import session_lock

    with failures_announced(bus):
        if options.artefact is not None:
            return _scan_artefacts(options, bus, t0)
        with ExitStack() as held:
            if options.resume is not None and (options.folder / SESSION_FILE).is_file():
                held.enter_context(session_lock(options.folder))
            process_options = options.processing
            streaming = None
            if options.process:   # the STREAMING placement: each view's steps as it comes, on the runner's worker
                from rangekit.app.scan.streaming import StreamingViews

                streaming = StreamingWorker(StreamingViews(options.folder, process_options, bus))
                bus.subscribe(streaming.on_event, first=True)
                held.callback(streaming.stop)     # an error or Ctrl-C: the view being decoded finishes, no more
            session = _acquire(options, bus, None if streaming is None else streaming.steps.quiet)
            acquisition_s = time.perf_counter() - t0
            if not options.process:
                return ScanResult(options.folder, session, acquisition_s, None, time.perf_counter() - t0)
            bus.flush()               # every view acquired is queued for the streaming worker
            streaming.drain()
            if streaming.steps.moved:   # the object moved during some views: each taken once more
                bus.unsubscribe(streaming.on_event)
                session = _take_again(options, session, streaming.steps.moved, bus)
            processed = _preview_then_process(streaming, session, process_options, bus)
    return ScanResult(options.folder, session, acquisition_s, processed, time.perf_counter() - t0)


def _preview_then_process(streaming: StreamingWorker, session: Session, options: ProcessOptions,
                          on_event) -> ProcessResult:
    """After the acquisition, every view drained (:meth:`StreamingWorker.drain`): the preview written first, on
    this thread, then the processing with what the streaming did ahead (:meth:`StreamingWorker.memo`: the last
    views' work ahead, then the stages). The preview is what a person waits for first: written beside the
    processing, its 0.08-0.1 CPU-s took 0.1-0.2 s on an idle machine, waiting for the GIL and the cores the
    registration and the last views' work ahead held (issue 51: the preview within 1 s of the last frame). A
    failure of the preview is raised after the processing, its meshes written. The blocks fusion's volume is
    finished beside the processing (its last views and marching cubes, beside the last views' work ahead and the
    registration); the processing waits for it before it takes the volume (``Memo.before_mesh``)."""
    with start(Where.HERE, streaming.write_preview) as preview:
        with start(Where.THREAD, streaming.finish_blocks) as blocks:
            memo = streaming.memo()
            memo.before_mesh = _waiting(blocks)
            processed = _process(session, options, on_event, Plan.STREAMING, memo)
            blocks.result()
        preview.result()
    return processed


def _waiting(call):
    """A call that waits for ``call`` to end, its error left to ``call.result()`` afterwards."""
    def wait() -> None:
        try:
            call.result()
        except Exception:   # noqa: BLE001 - raised by the scan's own preview.result() after the processing
            pass
    return wait


def _take_again(options: ScanOptions, session: Session, moved: dict, on_event: OnEvent | None) -> Session:
    """The views the object moved during (``moved``: index -> the streaming's MotionError) taken once more: marked
    pending, then the acquisition resumed (the simulator's knock, ``sim_bump``, is not repeated). The processing
    checks them again, and refuses one that moved again, naming it."""
    from dataclasses import replace

    progress = progress_of(on_event)
    for k, error in sorted(moved.items()):
        progress(f"view {k}: {str(error).split(': ', 1)[-1]}; taking it again")
        session = session.with_view_done(k, done=False)
    session.save()
    return _acquire(replace(options, out=None, resume=options.folder, sim_bump=None), on_event)


def _acquire(options: ScanOptions, on_event: OnEvent | None, quiet=None) -> Session:
    """Set up, then acquire every view not yet done (the stage "acquire"); ``quiet``: the capture's waits told to
    the streaming processing (:class:`rangekit.app.acquire.quiet.QuietWindows`)."""
    from rangekit.app.acquire.acquire import acquire
    from rangekit.app.scan.setup import prepare_scan

    progress = progress_of(on_event)
    setup = prepare_scan(options, progress)
    try:
        spec = setup.spec
        emit(on_event, ScanStarted(setup.folder, setup.n_views, setup.n_done, spec.n_frames, setup.resume,
                                   setup.exposures_us,
                                   isinstance(spec, LaserSequence)))
        turn_over = None
        if setup.hardware is not None and setup.passes > 1:   # the simulator turns its object over itself
            from rangekit.app.scan.passes import turn_over_prompt

            turn_over = turn_over_prompt(setup.folder, setup.passes, flipped=options.flipped)
        if options.sim_bump is not None and setup.simulator is not None:
            _knock(setup, *options.sim_bump)
        with StageClock(on_event).stage(Stage.ACQUIRE):
            return acquire(setup.devices, setup.rig, spec, setup.folder,
                           plan=ScanPlan(n_views=setup.n_views, passes=setup.passes), resume=setup.resume,
                           capture=setup.capture, simulator=setup.simulator, hardware=setup.hardware,
                           files=setup.files, progress=progress, allow_auto_exposure=options.allow_auto_exposure,
                           turn_over=turn_over, on_event=on_event, quiet=quiet)
    finally:
        setup.close()


def _knock(setup, view: int, frame: int, mm: float) -> None:
    """``sim_bump``: the simulated object knocked ``mm`` along the world x axis from frame ``frame`` of view ``view``
    (counted among the views still to take, every exposure) to the end of that view, then back in place."""
    import numpy as np

    todo = [v.index for v in Session.load(setup.folder).views if not v.done] if setup.resume else \
        list(range(setup.n_views))
    if view not in todo:
        return
    per_view = setup.spec.n_frames * max(1, len(setup.exposures_us or ()))
    T = np.eye(4)
    T[0, 3] = mm * 1e-3
    before = todo.index(view) * per_view + frame
    setup.devices.inject_motion(T, after=before, frames=per_view - frame)


def _scan_artefacts(options: ScanOptions, on_event: OnEvent | None, t0: float) -> ScanResult:
    """``artefact="vdi2634"``: one single-view capture per artefact position, written to ``out/vdi2634.json``."""
    from rangekit.app.scan.vdi2634 import run_vdi2634
    from rangekit.errors import OptionError
    from rangekit.sim.scene.artefacts import GUIDELINE_POSITIONS

    counts = tuple(options.positions) if options.positions is not None else GUIDELINE_POSITIONS
    for n, most, what in zip(counts, GUIDELINE_POSITIONS, ("sphere", "ball bar", "plane")):
        if not 0 <= n <= most:
            raise OptionError(f"{{positions}}: {what} positions must be in 0..{most}, found {n}")
    if not any(counts):
        raise OptionError(f"{{positions}}: expected at least one artefact position, found "
                          f"{' '.join(map(str, counts))}")
    rig = None if options.rig in (None, "sim") else str(options.rig)
    if rig is not None and not Path(rig).is_file():
        raise OptionError(f"{{rig}} {rig}: expected a rig file from 'rangekit calibrate', found "
                          f"{'a folder' if Path(rig).is_dir() else 'no such file'}")
    res = run_vdi2634(options.out, rig_file=rig, n_spheres=counts[0], n_bars=counts[1], n_planes=counts[2],
                      seed=0 if options.seed is None else options.seed, progress=progress_of(on_event))
    seconds = time.perf_counter() - t0
    return ScanResult(Path(options.out), None, seconds, None, seconds, vdi2634=res)


#: The hand-over keywords ``rk.process`` took before issue 49: the scan's live processing now hands its work on
#: through the job runner's memo (:class:`rangekit.app.runner.Memo`), and Dask places the pairs itself.
REMOVED_KEYWORDS = ("decoded_views", "registration_ahead", "map_pairs")


def process(session: Session | str | Path, options: ProcessOptions | None = None, *,
            on_event=None, evaluate: Evaluator | None = None, **removed) -> ProcessResult:
    """Process a session (loaded, or its folder) as ``rangekit process`` does: :func:`process_session` with the
    simulator's truth as evaluator when the session is simulated and ``options.truth`` (the session loaded once
    and handed on; ``evaluate``: another evaluator). ``on_event``: see :mod:`rangekit.app.events`.

    The keywords ``decoded_views``, ``registration_ahead`` and ``map_pairs`` were removed (issue 49): what a scan
    does while its views come reaches processing inside the job runner (:class:`rangekit.app.runner.Memo`); given,
    they are an InputError naming them."""
    from rangekit.errors import InputError

    for name in removed:
        raise InputError(f"{name}: not a keyword of rk.process (found {name}=...); "
                         + (f"{name} was removed in issue 49: a scan hands its work on to processing inside the job "
                            "runner (rangekit.app.runner.Memo), a Dask batch places its pairs itself"
                            if name in REMOVED_KEYWORDS else "expected session, options, on_event or evaluate"))
    if not isinstance(session, Session):
        check_path("session", session, what="a Session or a session folder")
    check_instance("options", options, ProcessOptions, "a ProcessOptions", optional=True)
    for name, value in (("on_event", on_event), ("evaluate", evaluate)):
        check_callable(name, value)
    return _process(session, options or ProcessOptions(), on_event, Plan.LOCAL, Memo(evaluate=evaluate))


def _process(session: Session | str | Path, options: ProcessOptions, on_event, plan: Plan, memo: Memo) -> ProcessResult:
    """:func:`process` placed by ``plan``, with ``memo`` (its evaluator, else the simulator's truth when
    ``options.truth``)."""
    with failures_announced(on_event):
        if not isinstance(session, Session):
            if not (Path(session) / SESSION_FILE).is_file():
                raise ConfigError(f"{session}: not a session folder (no {SESSION_FILE})")
            session = Session.load(session)
        on_event = logged(session.folder, on_event)
        evaluate = memo.evaluate
        if not options.truth:
            evaluate = None
        elif evaluate is None:
            evaluate = session_evaluator(session)
        evaluate = measuring(evaluate)      # NO_TRUTH (hardware): no evaluation
    return process_session(session, options, evaluate=evaluate, on_event=on_event, plan=plan, memo=memo)


def process_placed(session: Session | str | Path, options: ProcessOptions, *, plan: Plan,
                   on_event=None, memo: Memo | None = None) -> ProcessResult:
    """:func:`process` as a placement of the plan runs it (a Dask session task: ``Plan.DASK``, its ``memo`` the
    views its view tasks decoded)."""
    return _process(session, options, on_event, plan, memo if memo is not None else Memo())
