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
from rangekit._runtime.child import call_beside
from rangekit.app.event_log import logged
from rangekit.app.events import OnEvent, ScanStarted, StageClock, emit, failures_announced, progress_of
from rangekit.app.process.evaluate import Evaluator, measuring
from rangekit.app.process.options import ProcessOptions
from rangekit.app.process.process import process_session
from rangekit.app.scan.options import ScanOptions
from rangekit.app.scan.truth import session_evaluator
from rangekit.errors import ConfigError
from rangekit.formats.sessions.session import ScanPlan, Session
from rangekit.formats.sessions.summary import ProcessResult
from rangekit.laser.sequence import LaserSequence

if TYPE_CHECKING:
    from rangekit.app.scan.vdi2634 import Vdi2634Result

__all__ = ["ScanResult", "scan", "session_evaluator", "process"]


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
    from rangekit.formats.sessions.lock import session_lock

    check_instance("options", options, ScanOptions, "a ScanOptions (rk.scan(rk.ScanOptions(out=FOLDER)))")
    check_callable("on_event", on_event)
    on_event = logged(options.folder, on_event)     # events.jsonl in the session folder (rangekit.app.event_log)

    t0 = time.perf_counter()
    with failures_announced(on_event):
        if options.artefact is not None:
            return _scan_artefacts(options, on_event, t0)
        with ExitStack() as held:
            if options.resume is not None and (options.folder / "session.json").is_file():
                held.enter_context(session_lock(options.folder))
            process_options = options.processing
            one_at_a_time, streaming = _serialised(on_event), None
            if options.process:
                from rangekit.app.scan.streaming import StreamingProcessor

                streaming = StreamingProcessor(options.folder, process_options, on_event, lock=one_at_a_time.lock)
                held.callback(streaming.stop)     # an error or Ctrl-C: the view being decoded finishes, no more
            session = _acquire(options, one_at_a_time.chained(streaming),
                               None if streaming is None else streaming.quiet)
            acquisition_s = time.perf_counter() - t0
            if not options.process:
                return ScanResult(options.folder, session, acquisition_s, None, time.perf_counter() - t0)
            streaming.drain()
            if streaming.moved:       # the object moved during some views: each taken once more
                session = _take_again(options, session, streaming.moved, one_at_a_time.chained(None))
            with call_beside(streaming.write_preview, in_child=False) as preview:   # the preview beside the processing
                processed = process(session, process_options, on_event=on_event, decoded_views=streaming.results,
                                    evaluate=streaming.evaluate, registration_ahead=streaming.registration)
                preview.result()
    return ScanResult(options.folder, session, acquisition_s, processed, time.perf_counter() - t0)


class _serialised:
    """The scan's subscriber given one event at a time from any thread (the capture's, the frame writer's, the
    streaming processor's): each call holds ``lock``."""

    def __init__(self, on_event: OnEvent | None) -> None:
        import threading

        self.on_event, self.lock = on_event, threading.Lock()

    def chained(self, streaming) -> OnEvent:
        """The subscriber acquisition is given: the streaming processor's first (it queues views), then the
        scan's."""
        def on_event(event) -> None:
            with self.lock:
                if streaming is not None:
                    streaming.on_event(event)
                emit(self.on_event, event)
        return on_event


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
        with StageClock(on_event).stage("acquire"):
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


def process(session: Session | str | Path, options: ProcessOptions | None = None, *,
            on_event=None, map_pairs=None, decoded_views: dict | None = None, evaluate: Evaluator | None = None,
            registration_ahead=None) -> ProcessResult:
    """Process a session (loaded, or its folder) as ``rangekit process`` does: :func:`process_session` with the
    simulator's truth as evaluator when the session is simulated and ``options.truth`` (the session loaded once
    and handed on). ``on_event``: see :mod:`rangekit.app.events`; what the scan did while its views came
    (:class:`rangekit.app.scan.streaming.StreamingProcessor`): ``decoded_views`` the views it decoded,
    ``evaluate`` its evaluator (the truth's samples and each view's errors made), ``registration_ahead`` its
    :class:`rangekit.registration.ahead.RegistrationAhead`; the outputs are the same bytes with or without them."""
    from rangekit.app.events import failures_announced
    from rangekit.registration.ahead import RegistrationAhead

    if not isinstance(session, Session):
        check_path("session", session, what="a Session or a session folder")
    check_instance("options", options, ProcessOptions, "a ProcessOptions", optional=True)
    for name, value in (("on_event", on_event), ("map_pairs", map_pairs), ("evaluate", evaluate)):
        check_callable(name, value)
    check_instance("decoded_views", decoded_views, dict, "a dict of decoded views", optional=True)
    check_instance("registration_ahead", registration_ahead, RegistrationAhead, "a RegistrationAhead", optional=True)
    options = options or ProcessOptions()
    with failures_announced(on_event):
        if not isinstance(session, Session):
            if not (Path(session) / "session.json").is_file():
                raise ConfigError(f"{session}: not a session folder (no session.json)")
            session = Session.load(session)
        on_event = logged(session.folder, on_event)
        if not options.truth:
            evaluate = None
        elif evaluate is None:
            evaluate = session_evaluator(session)
        evaluate = measuring(evaluate)      # NO_TRUTH (hardware): no evaluation
    return process_session(session, options, evaluate=evaluate, on_event=on_event, map_pairs=map_pairs,
                           decoded_views=decoded_views, registration_ahead=registration_ahead)
