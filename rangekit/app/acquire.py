"""Crash-safe acquisition sessions: turn the table, project every pattern, capture, write to disk.

The same code drives the simulated rig and real hardware: it only uses the device protocols
(:mod:`rangekit.devices`). A session directory holds::

    session.json          manifest (schema rangekit.session/1): plan, pattern spec, each view's state
    rig.json              the rig file (calibration) the session was taken with
    patterns.json         the PatternSpec
    view_000/000.png ...  one folder per completed view (+ view.json with its angle and timing, and copies
                          of patterns.json and rig.json: each view is a capture folder on its own)

Every file is written atomically. A view is captured into ``view_NNN.partial/`` and renamed to
``view_NNN/`` only when all its frames are on disk, then ``session.json`` records it as done; so a fault
at any moment leaves every completed view intact, and ``acquire(..., resume=True)`` redoes only the
view that was interrupted and the ones after it.
"""

from __future__ import annotations

import shutil
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from rangekit.devices import Rig as RigDevices
from rangekit.errors import ConfigError, DeviceError
from rangekit.io import atomic_write_json, read_json, write_png
from rangekit.coded.patterns import PatternSpec
from rangekit.progress import call_progress
from rangekit.rig import Rig, save_rig

__all__ = ["ScanPlan", "SessionView", "acquire", "load_session", "SESSION_SCHEMA"]

SESSION_SCHEMA = "rangekit.session/1"


@dataclass(frozen=True)
class ScanPlan:
    """What to acquire: ``n_views`` turntable angles ``start + k * step`` (radians)."""

    n_views: int = 12
    step: float | None = None     # radians; default a full turn / n_views
    start: float = 0.0            # radians

    def angles(self) -> np.ndarray:
        step = self.step if self.step is not None else 2 * np.pi / self.n_views
        return self.start + step * np.arange(self.n_views)


@dataclass(frozen=True)
class SessionView:
    index: int
    angle: float    # radians
    done: bool
    folder: Path


def _view_dir(out: Path, k: int) -> Path:
    return out / f"view_{k:03d}"


def _manifest(plan: ScanPlan, spec: PatternSpec, done: list[bool], extra: dict) -> dict:
    return {"schema": SESSION_SCHEMA, "plan": {**asdict(plan), "angles_rad": plan.angles().tolist()},
            "pattern": spec.to_dict(), "views": [{"index": k, "angle_rad": float(a), "state": "done" if d else "pending",
                                                  "folder": f"view_{k:03d}"}
                                                 for k, (a, d) in enumerate(zip(plan.angles(), done))], **extra}


def load_session(folder: str | Path) -> tuple[dict, list[SessionView]]:
    """The manifest and each view's state; a view counts as done only if its folder is complete."""
    out = Path(folder)
    data = read_json(out / "session.json", what="session manifest")
    if data.get("schema") != SESSION_SCHEMA:
        raise ConfigError(f"{out / 'session.json'}: schema must be {SESSION_SCHEMA!r}, found {data.get('schema')!r}")
    n_frames = len(data["pattern"]["frames"])
    views = []
    for v in data["views"]:
        d = _view_dir(out, v["index"])
        complete = v["state"] == "done" and (d / "view.json").exists() and len(list(d.glob("[0-9][0-9][0-9].png"))) == n_frames
        views.append(SessionView(v["index"], v["angle_rad"], complete, d))
    return data, views


def acquire(devices: RigDevices, rig: Rig, spec: PatternSpec, out_dir: str | Path, *, plan: ScanPlan = ScanPlan(),
            resume: bool = False, settle_s: float = 0.0, pattern_settle_s: float = 0.0, extra: dict | None = None,
            progress: Callable[[str], None] | None = None) -> list[SessionView]:
    """Acquire (or resume) a session.

    Parameters
    ----------
    devices : an object with ``camera``, ``projector`` and ``turntable`` (may be None for one view).
    rig : the rig file written with the session (calibration).
    spec : the pattern set projected at every view.
    out_dir : session folder. A folder that already holds a session is refused unless ``resume``.
    plan : turntable angles.
    resume : continue the session in ``out_dir``; its plan and pattern must equal these.
    settle_s : wait after each turntable move (vibration).
    pattern_settle_s : wait after each pattern is shown, for the projector's display latency, so the
        camera (which only returns frames exposed after ``capture()`` is called) sees the new pattern.
    extra : more fields for session.json (e.g. the simulator's seed and object).
    progress : ``progress(msg, done=None, total=None)`` (see :mod:`rangekit.progress`).

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
        data, views = load_session(out)
        old = np.asarray(data["plan"]["angles_rad"])
        if data["pattern"] != spec.to_dict() or old.shape != angles.shape or not np.allclose(old, angles):
            raise ConfigError(f"{out}: the session was taken with another plan or pattern "
                              f"({len(data['plan']['angles_rad'])} views, pattern {data['pattern']['method']!r}); "
                              "resume it with the same settings")
        done = [v.done for v in views]
        extra = {k: v for k, v in data.items() if k not in ("schema", "plan", "pattern", "views")}
    else:
        if resume:
            raise ConfigError(f"{out}: no session.json to resume")
        out.mkdir(parents=True, exist_ok=True)
        done = [False] * plan.n_views
        save_rig(rig, out / "rig.json")
        atomic_write_json(out / "patterns.json", spec.to_dict())
        atomic_write_json(out / "session.json", _manifest(plan, spec, done, extra or {}))
    frames = list(spec.frames())
    names = spec.frame_names
    for k, angle in enumerate(angles):
        if done[k]:
            continue
        final = _view_dir(out, k)
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
        atomic_write_json(out / "session.json", _manifest(plan, spec, done, extra or {}))
        call_progress(progress, f"view {k + 1}/{plan.n_views} done ({len(frames)} frames, {time.time() - t0:.1f} s)",
                      k + 1, plan.n_views)
    return load_session(out)[1]
