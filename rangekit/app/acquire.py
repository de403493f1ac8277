"""Crash-safe acquisition sessions: turn the table, project every pattern, capture, write to disk.

The same code drives the simulated rig and real hardware: it only uses the device protocols
(:mod:`rangekit.devices`). The session folder's layout and manifest are :mod:`rangekit.formats.session`;
each view folder also holds ``view.json`` (its angle and timing) and copies of ``patterns.json`` and
``rig.json``, so each view is a capture folder on its own.

Every file is written atomically. A view is captured into ``view_NNN.partial/`` and renamed to
``view_NNN/`` only when all its frames are on disk, then ``session.json`` records it as done; so a fault
at any moment leaves every completed view intact, and ``acquire(..., resume=True)`` redoes only the
view that was interrupted and the ones after it.
"""

from __future__ import annotations

import shutil
import time
from pathlib import Path
from typing import Callable

import numpy as np

from rangekit.coded.patterns import PatternSpec
from rangekit.devices import Rig as RigDevices
from rangekit.errors import ConfigError, DeviceError
from rangekit.formats.session import CaptureSettings, ScanPlan, Session, SimulatorSettings, view_folder
from rangekit.io import atomic_write_json, write_png
from rangekit.progress import call_progress
from rangekit.rig import Rig, save_rig

__all__ = ["acquire"]


def acquire(devices: RigDevices, rig: Rig, spec: PatternSpec, out_dir: str | Path, *, plan: ScanPlan = ScanPlan(),
            resume: bool = False, capture: CaptureSettings | None = None,
            simulator: SimulatorSettings | None = None, hardware: dict | None = None,
            progress: Callable[[str], None] | None = None) -> Session:
    """Acquire (or resume) a session.

    Parameters
    ----------
    devices : an object with ``camera``, ``projector`` and ``turntable`` (may be None for one view).
    rig : the rig file written with the session (calibration).
    spec : the pattern set projected at every view.
    out_dir : session folder. A folder that already holds a session is refused unless ``resume``.
    plan : turntable angles.
    resume : continue the session in ``out_dir``; its plan and pattern must equal these. The session's
        own capture settings, simulator and hardware records are kept.
    capture : bit depth and waits; default :meth:`CaptureSettings.from_rig` (waits only on hardware).
        ``turntable_settle_s`` is waited after each turntable move (vibration), ``pattern_delay_s`` after
        each pattern is shown, for the projector's display latency, so the camera (which only returns
        frames exposed after ``capture()`` is called) sees the new pattern.
    simulator, hardware : how the views are taken, recorded in session.json (see :class:`Session`).
    progress : ``progress(msg, done=None, total=None)`` (see :mod:`rangekit.progress`).

    Returns
    -------
    Session
        The session as on disk, every view's state.

    Raises
    ------
    ConfigError
        The folder holds another session (without ``resume``), or the resumed session's plan or pattern
        differ from these.
    DeviceError
        A device failed; the message names the device, the view and the frame. Completed views stay on
        disk and ``resume=True`` continues.
    """
    out = Path(out_dir)
    angles = plan.angles()
    if (out / "session.json").exists():
        if not resume:
            raise ConfigError(f"{out}: already holds a session (session.json); use resume to continue it or "
                              "choose another folder")
        session = Session.load(out)
        old = session.plan.angles()
        if session.pattern != spec or old.shape != angles.shape or not np.allclose(old, angles):
            raise ConfigError(f"{out}: the session was taken with another plan or pattern "
                              f"({len(old)} views, pattern {session.pattern.method!r}); "
                              "resume it with the same settings")
    else:
        if resume:
            raise ConfigError(f"{out}: no session.json to resume")
        out.mkdir(parents=True, exist_ok=True)
        session = Session.new(out, plan, spec, rig, capture=capture, simulator=simulator, hardware=hardware)
        save_rig(rig, out / "rig.json")
        atomic_write_json(out / "patterns.json", spec.to_dict())
        session.save()
    settle_s, pattern_settle_s = session.capture.turntable_settle_s, session.capture.pattern_delay_s
    done = [v.done for v in session.views]
    frames = list(spec.frames())
    names = spec.frame_names
    for k, angle in enumerate(angles):
        if done[k]:
            continue
        final = view_folder(out, k)
        partial = out / f"view_{k:03d}.partial"
        shutil.rmtree(partial, ignore_errors=True)
        shutil.rmtree(final, ignore_errors=True)
        partial.mkdir(parents=True)
        t0 = time.time()
        step = "turntable move"
        try:
            if devices.turntable is not None:
                call_progress(progress, f"view {k + 1}/{plan.n_views}: turntable to {np.degrees(angle):.1f} deg",
                              k, plan.n_views)
                devices.turntable.rotate_to(float(angle))
                if settle_s > 0:
                    time.sleep(settle_s)
            for i, (name, frame) in enumerate(zip(names, frames)):
                step = f"frame {i} ({name}): projector"
                devices.projector.show(frame)
                if pattern_settle_s > 0:
                    time.sleep(pattern_settle_s)
                step = f"frame {i} ({name}): camera"
                image = devices.camera.capture()
                write_png(partial / f"{i:03d}.png", image)
        except DeviceError as exc:
            raise type(exc)(f"view {k} (turntable {np.degrees(angle):.1f} deg), {step}: {exc}; {sum(done)} completed "
                            f"view(s) are safe in {out}; continue with resume") from exc
        # Each view is a self-contained capture folder (rangekit reconstruct view_NNN works on it).
        atomic_write_json(partial / "patterns.json", spec.to_dict())
        save_rig(rig, partial / "rig.json")
        atomic_write_json(partial / "view.json", {"index": k, "angle_rad": float(angle), "started": t0,
                                                  "finished": time.time(), "n_frames": len(frames)})
        partial.rename(final)
        done[k] = True
        session = session.with_view_done(k)
        session.save()
        call_progress(progress, f"view {k + 1}/{plan.n_views} done ({len(frames)} frames, {time.time() - t0:.1f} s)",
                      k + 1, plan.n_views)
    return Session.load(out)
