"""Crash-safe acquisition sessions: turn the table, project every pattern, capture, write to disk.

The same code drives the simulated rig and real hardware: it only uses the device protocols
(:mod:`rangekit.rig.devices`). The session folder's layout and manifest are :mod:`rangekit.formats.sessions.session`;
each view folder also holds ``view.json`` (its angle and timing) and copies of ``patterns.json`` and
``rig.json``, so each view is a capture folder on its own.

Every file is written atomically. A view is captured into ``view_NNN.partial/`` and renamed to
``view_NNN/`` only when all its frames are on disk, then ``session.json`` records it as done; so a fault
at any moment leaves every completed view intact, and ``acquire(..., resume=True)`` redoes only the
view that was interrupted and the ones after it.

A device that goes away mid-view is waited for up to the rig file's ``devices.<device>.reconnect_timeout_s``
(:mod:`rangekit.app.acquire.reconnect`); once it is back, the view in progress is taken again from its turntable
move, its frames taken so far dropped, so the session is the one an uninterrupted scan records. A device not
back in time ends the scan as any device fault does.

Each frame's SHA-256 is taken from the bytes written and recorded with its view in ``session.json``; a
resume first checks the finished views against them (:mod:`rangekit.formats.sessions.check`). The
session folder is locked (:mod:`rangekit.formats.sessions.lock`) while acquisition runs. A file that
cannot be written (full disk) stops with a :class:`StorageError` that says how to resume; the view being
captured is removed, the finished ones stay.
"""

from __future__ import annotations

import shutil
import threading
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np

from rangekit.rig.camera_controls import controls_from_capture, require_locked
from rangekit.coded.patterns import PatternSpec
from rangekit.laser.sequence import LaserSequence
from rangekit.rig.devices import RigDevices
from rangekit.errors import ConfigError, DeviceError, MissedTrigger, StorageError
from rangekit.formats.sessions.session import (CaptureSettings, ScanPlan, Session, SimulatorSettings, exposure_folder,
                                               frame_files, view_folder)
from rangekit.formats.sessions.check import verify_views
from rangekit.formats.sessions.lock import session_lock
from rangekit.app.acquire.frame_writer import FrameError, FrameWriter
from rangekit.app.events import CaptureLoad, FramesWritten, OnEvent, ViewAcquired, emit
from rangekit.app.acquire.lights import light_for
from rangekit.app.acquire.quiet import QuietWindows, quiet_window
from rangekit.app.acquire.reconnect import MAX_RETAKES, reconnected
from rangekit.app.acquire.triggered import take_triggered, uses_trigger
from rangekit.io import atomic_write_bytes, atomic_write_json, fsync_folder
from rangekit.progress import LOGGER, call_progress
from rangekit.rig.rig_file import Rig, save_rig
from rangekit.formats.sessions.files import PATTERNS_FILE, RIG_FILE, SESSION_FILE, VIEW_FILE, partial_view_folder

__all__ = ["acquire"]


def acquire(devices: RigDevices, rig: Rig, spec: PatternSpec, out_dir: str | Path, *, plan: ScanPlan = ScanPlan(),
            resume: bool = False, capture: CaptureSettings | None = None,
            simulator: SimulatorSettings | None = None, hardware: dict | None = None,
            files: dict[str, bytes] | None = None, progress: Callable[[str], None] | None = None,
            allow_auto_exposure: bool = False, turn_over: Callable[[int], None] | None = None,
            on_event: OnEvent | None = None, quiet: QuietWindows | None = None) -> Session:
    """Acquire (or resume) a session.

    Parameters
    ----------
    devices : an object with ``camera``, ``projector`` and ``turntable`` (may be None for one view).
    rig : the rig file written with the session (calibration).
    spec : the pattern set projected at every view.
    out_dir : session folder. A folder that already holds a session is refused unless ``resume``.
    plan : turntable angles and passes.
    resume : continue the session in ``out_dir``; its plan and pattern must equal these. The session's
        own capture settings, simulator and hardware records are kept.
    capture : bit depth and waits; default :meth:`CaptureSettings.from_rig` (waits only on hardware).
        ``turntable_settle_s`` is waited after each turntable move (vibration), ``pattern_delay_s`` after
        each pattern is shown, for the projector's display latency, so the camera (which only returns
        frames exposed after ``capture()`` is called) sees the new pattern.
    simulator, hardware : how the views are taken, recorded in session.json (see :class:`Session`).
    files : files a new session keeps, relative name -> bytes (a simulated object's mesh, ``object/NAME``).
    progress : ``progress(msg, done=None, total=None)`` (see :mod:`rangekit.progress`).
    allow_auto_exposure : scan although the rig's ``capture.camera.exposure_us`` is "auto" (``rangekit scan
        --allow-auto-exposure``); otherwise that is refused before any frame. The rig's camera controls
        are applied (``camera.set_controls``, where the camera has it) before the first frame.
    turn_over : a multi-pass plan (``plan.passes`` > 1): ``turn_over(p)`` is called before the first view of
        pass ``p`` (p >= 1) when no view of that pass is done yet, once every earlier view is on disk: on
        hardware it asks the user to turn the object over (:func:`rangekit.app.scan.passes.turn_over_prompt`);
        an error it raises stops the scan there, resumable. Devices with ``start_pass(p)`` (the simulator)
        are told each view's pass before it is taken (they turn the object over themselves).
    on_event : given :class:`rangekit.app.events.ViewAcquired` as each view is recorded done (from the frame
        writer's thread, one at a time with ``progress``).
    quiet : told each wait on the devices (pattern delay, turntable settling) as it begins and ends, and the
        end of the acquisition (:class:`rangekit.app.acquire.quiet.QuietWindows`): work beside the capture
        starts its long GIL-holding calls in them.

    Returns
    -------
    Session
        The session as on disk, every view's state.

    Raises
    ------
    ConfigError
        The folder holds another session (without ``resume``), or the resumed session's plan or pattern
        differ from these, or its session.json is malformed.
    FileFormatError
        A finished view's frames differ from the SHA-256s recorded in session.json (resume).
    SessionLocked
        Another process is working on the session folder.
    StorageError
        A file cannot be written (full disk); the message says how to resume.
    DeviceError
        A device failed (and, if it went away, did not come back within its ``reconnect_timeout_s``); the
        message names the device, the view and the frame. Completed views stay on disk and ``resume=True``
        continues.
    """
    out = Path(out_dir)
    controls = controls_from_capture(rig.capture, where="rig file")
    if allow_auto_exposure:
        controls = replace(controls, allow_auto_exposure=True)
    require_locked(controls, where="rig file", method="laser-line scanning" if isinstance(spec, LaserSequence)
                   else "coded light")
    if (out / SESSION_FILE).exists():
        if not resume:
            raise ConfigError(f"{out}: already holds a session ({SESSION_FILE}); use resume to continue it or "
                              "choose another folder")
    elif resume:
        raise ConfigError(f"{out}: no {SESSION_FILE} to resume")
    else:
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise StorageError(f"{out}: cannot create the session folder: {exc.strerror or exc}") from exc
        fsync_folder(out.parent)
    with session_lock(out):
        set_controls = getattr(devices.camera, "set_controls", None)
        if set_controls is not None:
            set_controls(controls)
        return _acquire(devices, rig, spec, out, plan, resume, capture, simulator, hardware, files or {}, progress,
                        controls, turn_over, on_event, quiet)


def _resume_hint(out: Path, n_done: int) -> str:
    return (f"{n_done} completed view(s) are safe in {out}; continue with: rangekit scan --resume {out} "
            "(or acquire(..., resume=True))")


def _new_session(out: Path, plan, spec, rig, capture, simulator, hardware, files: dict) -> Session:
    if (out / SESSION_FILE).exists():  # another process made it meanwhile
        raise ConfigError(f"{out}: already holds a session ({SESSION_FILE}); choose another folder")
    session = Session.new(out, plan, spec, rig, capture=capture, simulator=simulator, hardware=hardware)
    try:
        for name, data in files.items():
            atomic_write_bytes(out / name, data)
        save_rig(rig, out / RIG_FILE)
        atomic_write_json(out / PATTERNS_FILE, spec.to_dict())
        session.save()   # last: a folder with session.json has everything else
    except OSError as exc:
        raise StorageError(f"{getattr(exc, 'filename', None) or out}: cannot write the new session: "
                           f"{exc.strerror or exc}; free some space and start the scan again") from exc
    return session


def _acquire(devices, rig, spec, out: Path, plan, resume, capture, simulator, hardware, files,
             progress, controls, turn_over=None, on_event=None, quiet=None) -> Session:
    angles = plan.angles()
    if resume:
        session = Session.load(out)
        old = session.plan.angles()
        if (session.pattern != spec or old.shape != angles.shape or not np.allclose(old, angles)
                or session.plan.passes != plan.passes):
            raise ConfigError(f"{out}: the session was taken with another plan or pattern "
                              f"({len(old)} views in {session.plan.passes} pass(es), pattern "
                              f"{session.pattern.method!r}); "
                              "resume it with the same settings")
        unverified = verify_views(session)
        if unverified:
            call_progress(progress, f"{', '.join(unverified)}: no frame checksums in {SESSION_FILE} (written by an "
                                    "older rangekit); their frames are not verified")
    else:
        session = _new_session(out, plan, spec, rig, capture, simulator, hardware, files)
    exposures = session.capture.exposures_us or (None,)
    if exposures[0] is not None and (isinstance(spec, LaserSequence) or
                                     getattr(devices.camera, "set_controls", None) is None):
        raise ConfigError(f"{out}: capture.exposures_us (multi-exposure) needs a coded-light scan and a camera "
                          f"that sets its exposure (set_controls); found {type(devices.camera).__name__}"
                          + (" and a laser scan" if isinstance(spec, LaserSequence) else ""))
    light = light_for(devices, spec, rig)
    run = _Run(devices, light, rig, spec, frame_files(spec, None, session.capture.frame_format), out, plan,
               session.capture.turntable_settle_s,
               session.capture.pattern_delay_s,
               tuple((e, None if e is None else replace(controls, exposure_us=float(e))) for e in exposures),
               progress, on_event, quiet, uses_trigger(devices.camera, rig, spec))
    try:
        return _views(run, session, angles, turn_over)
    finally:
        if quiet is not None:
            quiet.end()
        light.close()


@dataclass(frozen=True, eq=False)
class _Run:
    """What every view of one acquisition is taken with: the devices and the light that shows the frames, the
    rig and the frame sequence written with each view, the waits (seconds) and the exposures
    (``(us, CameraControls)``; ``(None, None)``: the rig's one exposure)."""

    devices: object
    light: object
    rig: Rig
    spec: PatternSpec | LaserSequence
    files: list            # each frame's file in a view folder (Session.frame_files of one exposure)
    out: Path
    plan: ScanPlan
    settle_s: float
    pattern_settle_s: float
    exposures: tuple
    progress: Callable | None
    on_event: OnEvent | None
    quiet: QuietWindows | None = None
    triggered: bool = False    # frames on the projector's trigger (rangekit.app.acquire.triggered), no pattern delay
    lock: threading.Lock = field(default_factory=threading.Lock)

    def report(self, *args, **kwargs) -> None:
        """``progress``: frames are reported from the acquiring thread, views done from the writer's, one at a time."""
        with self.lock:
            call_progress(self.progress, *args, **kwargs)

    def announce(self, event) -> None:
        """``on_event``, one at a time with :meth:`report`."""
        with self.lock:
            emit(self.on_event, event)


def _views(run: _Run, session: Session, angles: np.ndarray, turn_over=None) -> Session:
    """Each view not done: turn, then for each exposure every frame, into the view folder or its exposure
    sub-folder ``e<us>/``. Frames are taken here in order and written behind by :class:`FrameWriter` (a
    simulated one rendered there too); a view is recorded done only once all its frames are on disk. Before
    the first view of a pass none of whose views is done, every earlier view is finished and ``turn_over(pass)``
    is called (hardware). Returns the session as recorded on disk."""
    done = [v.done for v in session.views]
    writer, current = _writer(run), [-1]
    state = {"session": session,   # one bar over every frame still to take (with the exposures), with an ETA
             "frames": [0, int(np.count_nonzero(~np.asarray(done, bool))) * len(run.exposures) * run.spec.n_frames]}
    plan, devices = run.plan, run.devices
    passes, start_pass, begun = plan.view_passes(), getattr(devices, "start_pass", None), set()
    try:
        for k, angle in enumerate(angles):
            if not done[k]:
                p = int(passes[k])
                if (p > 0 and turn_over is not None and p not in begun
                        and not any(done[i] for i in np.flatnonzero(passes == p))):
                    writer.close()      # every earlier view on disk before the object is touched
                    run.report(f"pass {p} of {plan.passes} done; the object is to be turned over")
                    turn_over(p)
                    writer = _writer(run)
                begun.add(p)
                if start_pass is not None:
                    start_pass(p)
                current[0] = k
                _take_view(run, k, angle, state, done, writer)
        current[0] = -1
        writer.close()
    except BaseException as exc:
        # An error or Ctrl-C: the current view's waiting frames are dropped, the views whose frames were all
        # taken are finished (recorded done) before the error is raised.
        writer.cancel_view()
        writer.close(raise_error=False)
        if isinstance(exc, FrameError):     # the earliest failure, whichever thread failed first
            _fail(run.out, current[0], writer.error or exc, done)
        raise
    return state["session"]


def _take_view(run: _Run, k: int, angle: float, state: dict, done: list, writer: FrameWriter) -> None:
    """:func:`_view`, taken again from its turntable move (its frames so far dropped) each time its device went away
    and came back (:func:`rangekit.app.acquire.reconnect.reconnected`) or its camera missed a trigger
    (:mod:`rangekit.app.acquire.triggered`), at most :data:`MAX_RETAKES` times. Before a view is taken again the
    simulator's noise restarts (``devices.restart_noise``), so it records the bytes of a view taken once."""
    for retake in range(MAX_RETAKES + 1):
        taken = state["frames"][0]
        try:
            return _view(run, k, angle, state, done, writer, retake=retake > 0)
        except FrameError as exc:
            if retake == MAX_RETAKES or not (_missed_trigger(run, exc) or reconnected(
                    run.devices, run.rig, exc, run.report, run.plan.n_views)):
                raise
            writer.drop_view()
            state["frames"][0] = taken
            restart_noise = getattr(run.devices, "restart_noise", None)
            if restart_noise is not None:
                restart_noise()


def _missed_trigger(run: _Run, exc: FrameError) -> bool:
    """Whether ``exc`` is a missed trigger (the view is then taken again); it is reported, naming the view and
    frame."""
    if not isinstance(exc.error, MissedTrigger):
        return False
    run.report(f"view {exc.view + 1}/{run.plan.n_views}, {exc.step}: {exc.error}; the view is taken again")
    return True


def _fail(out, k, exc: FrameError, done) -> None:
    """Raise the error of ``exc.step`` of view ``exc.view`` as acquisition states it; the unfinished views'
    partial folders (that view's and the current one, ``k``) are removed."""
    for index in {exc.view, k} - {-1}:
        shutil.rmtree(partial_view_folder(out, index), ignore_errors=True)
    where, error = f"view {exc.view} (turntable {np.degrees(exc.angle):.1f} deg), {exc.step}", exc.error
    if isinstance(error, DeviceError):
        raise type(error)(f"{where}: {error}; {_resume_hint(out, sum(done))}") from error
    if isinstance(error, OSError):
        raise StorageError(f"{where}: cannot write {exc.target}: {error.strerror or error}; free some space; "
                           f"{_resume_hint(out, sum(done))}") from error
    raise error


def _writer(run: _Run) -> FrameWriter:
    """The frame writer of an acquisition, its backlog announced (:class:`rangekit.app.events.CaptureLoad`)."""
    return FrameWriter(on_load=lambda behind, pending: run.announce(CaptureLoad(behind, pending)))


def _taken(camera):
    """A camera without deferred capture: its frame taken now (a copy: a driver may reuse its buffer)."""
    def capture():
        image = camera.capture()
        image = image.copy() if isinstance(image, np.ndarray) else image
        return lambda: image
    return capture


class _At:
    """The step a view is at, its file and its device: what a failure names (:class:`FrameError`)."""

    def __init__(self, target: Path) -> None:
        self.step, self.target, self.device = "turntable move", target, None

    def __call__(self, step: str, device: str | None, target: Path | None = None) -> None:
        self.step, self.device = step, device
        if target is not None:
            self.target = target


def _view(run: _Run, k: int, angle: float, state: dict, done: list, writer: FrameWriter, *,
          retake: bool = False) -> None:
    """Take view ``k``'s frames and hand them to ``writer``, with the view's finishing step; ``retake``: the view
    is taken again after a device came back, its light first put in a known state (``light.reset()``)."""
    out, devices, light, names, files = run.out, run.devices, run.light, run.spec.frame_names, run.files
    final = view_folder(out, k)
    partial = partial_view_folder(out, k)
    t0 = time.time()
    sleep = getattr(devices, "sleep", time.sleep)    # the simulator's virtual clock, else the real one
    real = not getattr(getattr(devices, "clock", None), "virtual", False)   # its sleeps take real time
    deferred = getattr(devices.camera, "capture_deferred", None)
    capture = deferred if deferred is not None else _taken(devices.camera)
    at = _At(partial)
    try:
        shutil.rmtree(partial, ignore_errors=True)
        shutil.rmtree(final, ignore_errors=True)
        partial.mkdir(parents=True)
        if retake:
            at(f"{light.device} reset before the view is taken again", light.device)
            light.reset()
        at("turntable move", "turntable")
        if devices.turntable is not None:
            LOGGER.debug("view %d/%d: turntable to %.1f deg", k + 1, run.plan.n_views, np.degrees(angle))
            with quiet_window(run.quiet if real else None):
                devices.turntable.rotate_to(float(angle))
                if run.settle_s > 0:
                    sleep(run.settle_s)
        for exposure, controls in run.exposures:
            sub = "" if exposure is None else f"{exposure_folder(exposure)}/"
            if exposure is not None:
                at(f"exposure {exposure} us: camera controls", None)
                (partial / sub).mkdir()
                at(f"exposure {exposure} us: camera controls", "camera")
                devices.camera.set_controls(controls)

            def record(i: int, image, sub=sub) -> None:
                state["frames"][0] += 1
                run.report(f"view {k + 1}/{run.plan.n_views}: {sub}frame {i + 1}/{len(names)}", *state["frames"])
                at(f"{sub}frame {i} ({names[i]}): writing", None, partial / sub / files[i])
                writer.frame(k, angle, sub + files[i], f"{sub}frame {i} ({names[i]})", at.target, image)

            if run.triggered:
                take_triggered(devices.camera, light, names, lambda step, device, sub=sub: at(sub + step, device),
                               record)
                continue
            for i, name in enumerate(names):
                at(f"{sub}frame {i} ({name}): {light.device}", light.device)
                light.show(i)
                if run.pattern_settle_s > 0:
                    with quiet_window(run.quiet if real else None, run.pattern_settle_s):
                        sleep(run.pattern_settle_s)
                at(f"{sub}frame {i} ({name}): camera", "camera")
                record(i, capture())
        at(f"after frame {len(names) - 1} ({names[-1]}): {light.device} off", light.device)
        light.show(None)
    except (DeviceError, OSError) as exc:
        raise FrameError(k, angle, at.step, at.target, exc, device=at.device) from exc

    def finish(sha256: dict) -> None:
        run.announce(FramesWritten(k, run.plan.n_views, len(sha256)))   # its last frame is on disk
        step, target = f"writing {VIEW_FILE}", partial
        try:
            # Each view is a self-contained capture folder (rangekit reconstruct view_NNN works on it).
            atomic_write_json(partial / PATTERNS_FILE, run.spec.to_dict())
            save_rig(run.rig, partial / RIG_FILE)
            atomic_write_json(partial / VIEW_FILE, {"index": k, "angle_rad": float(angle), "started": t0,
                                                      "finished": time.time(), "n_frames": len(sha256)})
            partial.rename(final)
            fsync_folder(out)
            step, target = "recording the view", out / SESSION_FILE
            state["session"] = state["session"].with_view_done(k, sha256)
            state["session"].save()
        except OSError as exc:
            raise FrameError(k, angle, step, target, exc) from exc
        done[k] = True
        run.report(f"view {k + 1}/{run.plan.n_views} done ({len(sha256)} frames, {time.time() - t0:.1f} s)")
        run.announce(ViewAcquired(k, run.plan.n_views, final, float(angle), len(sha256)))

    writer.finish_view(k, angle, partial, finish)
