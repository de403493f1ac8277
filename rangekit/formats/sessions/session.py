"""A scan session's manifest, ``session.json``, as one typed value (schema ``rangekit.session/1``).

A session folder (written by :func:`rangekit.app.acquire.acquire.acquire`) holds::

    session.json          this manifest: plan, pattern spec, capture settings, each view's state, and how
                          the views were taken ("simulator": object, seed, imaging; or "hardware": rig file)
    rig.json              the rig file (calibration) the session was taken with
    patterns.json         the PatternSpec
    view_000/000.png ...  one folder per completed view
    object/NAME.ply       a simulated session's object mesh, when it came from a file (copied at creation)
    .lock                 held (``flock``) by the process working on the session (:mod:`.session_lock`)

Each finished view records the SHA-256 of every frame file in ``views[k].sha256`` (``{"000.png": hex,
...}``); :func:`rangekit.formats.sessions.check.verify_views` checks them before processing or resuming.
Sessions written before checksums were recorded still load (their views are "unverified").

``Session.load`` checks every field (type, range, the views against the plan) and names session.json,
the field, what was expected and what was found; a simulated object's mesh file must lie inside the
session folder (``simulator.object`` is a built-in name or a relative path such as ``object/bunny.ply``).

:class:`Session` is the only reader and writer of ``session.json``; acquisition, processing, the report
and the command line use its fields. Sessions written before ``capture`` was recorded still load: their
bit depth comes from the simulator's imaging model, else from the rig file's ``capture.bits``.

Bit depth and full scale: ``Session.capture.bits`` is the camera's ADC bit depth, taken once, when the
session is made, from the rig file's ``capture.bits`` (the simulator's rig states its imaging model's
depth there). ``CaptureSettings.full_scale`` is ``2**bits - 1``: a 12-bit camera saving 16-bit PNGs
decodes with full scale 4095, not 65535. Without ``bits`` the images' dtype gives the full scale.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from rangekit.coded.patterns import PatternSpec
from rangekit.laser.sequence import LASER_METHOD, LaserSequence
from rangekit.errors import ConfigError, RangekitError, shown
from rangekit.formats.sessions.summary import ProcessResult
from rangekit.io import atomic_write_json, read_json
from rangekit.rig.rig_file import Rig, load_rig
from rangekit.rig.checks import camera_triggered
from rangekit.formats.sessions.object import object_source
from rangekit.formats.sessions.files import RIG_FILE, SESSION_FILE, view_folder

__all__ = ["SESSION_SCHEMA", "ScanPlan", "CaptureSettings", "SimulatorSettings", "SessionView", "Session",
           "load_session", "view_folder", "exposure_folder", "frame_files", "FRAME_FORMATS", "ProcessResult"]

SESSION_SCHEMA = "rangekit.session/1"
#: Waits on hardware when the rig file's ``capture`` section does not set them, seconds.
DEFAULT_PATTERN_DELAY_S = 0.1
DEFAULT_TURNTABLE_SETTLE_S = 0.5


@dataclass(frozen=True)
class ScanPlan:
    """What to acquire: ``n_views`` turntable angles in all, ``passes`` passes of ``n_views / passes`` views
    each (the object turned over between passes, :mod:`rangekit.app.scan.passes`); view ``k`` of a pass is at
    ``start + k * step`` (radians)."""

    n_views: int = 12
    step: float | None = None     # radians; default a full turn / views per pass
    start: float = 0.0            # radians
    passes: int = 1               # turntable passes; n_views is a multiple of it

    @property
    def views_per_pass(self) -> int:
        return self.n_views // self.passes

    def angles(self) -> np.ndarray:
        """(n_views,) float64 turntable angles, radians (each pass's in turn)."""
        per = self.views_per_pass
        step = self.step if self.step is not None else 2 * np.pi / per
        return self.start + step * (np.arange(self.n_views) % per)

    def view_passes(self) -> np.ndarray:
        """(n_views,) int: the pass (0, 1, ...) of each view."""
        return np.arange(self.n_views) // self.views_per_pass


@dataclass(frozen=True)
class CaptureSettings:
    """How the views were captured: the camera's bit depth and the waits (seconds) between steps."""

    bits: int | None = None             # camera ADC bit depth (8, 10, 12 or 16); None: the images' dtype
    pattern_delay_s: float = 0.0        # wait after showing each pattern (projector latency)
    turntable_settle_s: float = 0.0     # wait after each turntable move (vibration)
    exposures_us: tuple | None = None   # multi-exposure (HDR): each pattern at each of these exposures (us,
                                        # increasing), frames in view_NNN/e<us>/; None: one exposure
    frame_format: str = "png"           # the frame files: "png" (000.png) or "npy.zst" (000.npy.zst,
                                        # rangekit.npy_zst: 3x faster to read, 4x to write); a session
                                        # written before the choice existed has PNGs

    @property
    def full_scale(self) -> float | None:
        """The largest pixel value the camera gives, ``2**bits - 1``; None when ``bits`` is unknown."""
        return float((1 << self.bits) - 1) if self.bits else None

    @classmethod
    def from_rig(cls, rig: Rig, *, hardware: bool) -> "CaptureSettings":
        """The rig file's ``capture`` section; waits on hardware (defaults 0.1 s and 0.5 s), and on the
        simulator the pattern delay the rig file states (``rangekit check``'s measured latency), else none. A
        camera triggered by the projector (``capture.trigger`` "projector") waits no pattern delay."""
        c = rig.capture
        delay = 0.0 if camera_triggered(c) else c.get("pattern_delay_s", DEFAULT_PATTERN_DELAY_S if hardware else 0.0)
        if not hardware:
            return cls(bits=c.get("bits"), pattern_delay_s=float(delay))
        return cls(bits=c.get("bits"), pattern_delay_s=float(delay),
                   turntable_settle_s=float(c.get("turntable_settle_s", DEFAULT_TURNTABLE_SETTLE_S)))


@dataclass(frozen=True)
class SimulatorSettings:
    """A simulated session: the object (built-in name or mesh file), noise seed and imaging model.
    ``pass_motions``: in a multi-pass scan, each pass's rigid motion (4, 4, world frame, nested tuples) of
    the object from its pose in the first pass (the first is the identity): how the simulator turned it
    over. Ground truth only: processing never reads it (it finds the passes' poses from the data)."""

    object: str
    seed: int
    imaging: dict = field(default_factory=dict)   # rangekit.sim.ImagingModel fields
    pass_motions: tuple | None = None


@dataclass(frozen=True)
class SessionView:
    """One view's state as recorded: ``done`` once its folder holds every frame; ``sha256`` maps each frame
    file name to its SHA-256 (hex) for a done view (None: a session written before checksums)."""

    index: int
    angle: float    # radians
    done: bool
    folder: Path
    sha256: dict | None = field(default=None, hash=False)
    scan_pass: int = 0    # the turntable pass (0, 1, ...) the view belongs to


def exposure_folder(exposure_us: int) -> str:
    """The sub-folder of a view holding the frames at one exposure of a multi-exposure session: ``e2000``."""
    return f"e{int(exposure_us)}"


#: The frame formats a session may store (CaptureSettings.frame_format); new scans write the first.
FRAME_FORMATS = ("npy.zst", "png")


def frame_files(pattern, exposures_us, frame_format: str = "png") -> list[str]:
    """A view's frame files: the pattern's (``000.png ...``, or ``000.npy.zst ...`` in that ``frame_format``), or
    each exposure's folder of them (``e2000/000.png ...``)."""
    files = pattern.frame_files
    if frame_format != "png":
        files = [f.removesuffix(".png") + "." + frame_format for f in files]
    return files if not exposures_us else [f"{exposure_folder(e)}/{f}" for e in exposures_us for f in files]


@dataclass(frozen=True, eq=False)
class Session:
    """A session folder's manifest and rig. Build a new one with :meth:`new`, read one with :meth:`load`."""

    folder: Path
    plan: ScanPlan
    pattern: PatternSpec | LaserSequence   # coded light: the patterns; laser lines: off + one frame per laser
    rig: Rig
    capture: CaptureSettings
    views: tuple[SessionView, ...]
    simulator: SimulatorSettings | None = None
    hardware: dict | None = None       # {"rig_file": path} on hardware

    @classmethod
    def new(cls, folder: str | Path, plan: ScanPlan, pattern: PatternSpec | LaserSequence, rig: Rig, *,
            capture: CaptureSettings | None = None, simulator: SimulatorSettings | None = None,
            hardware: dict | None = None) -> "Session":
        """A session with every view pending; ``capture`` defaults to the rig file's settings."""
        if capture is None:
            capture = CaptureSettings.from_rig(rig, hardware=hardware is not None)
        views = tuple(SessionView(k, float(a), False, view_folder(folder, k), scan_pass=int(p))
                      for k, (a, p) in enumerate(zip(plan.angles(), plan.view_passes())))
        return cls(Path(folder), plan, pattern, rig, capture, views, simulator, hardware)

    @property
    def frame_files(self) -> list[str]:
        """The frame files of a view, relative to its folder: ``000.png ...``, or with several exposures
        ``e2000/000.png ... e8000/000.png ...`` (:func:`exposure_folder`)."""
        return frame_files(self.pattern, self.capture.exposures_us, self.capture.frame_format)

    @property
    def is_simulated(self) -> bool:
        return self.simulator is not None

    @property
    def is_laser(self) -> bool:
        """A laser-line session (its views are laser capture folders)."""
        return isinstance(self.pattern, LaserSequence)

    @property
    def done_views(self) -> list[SessionView]:
        return [v for v in self.views if v.done]

    @property
    def simulator_object(self) -> str | None:
        """The simulated object: a built-in name, or the path of its mesh file inside the session folder
        (checked by :meth:`load`); None on hardware."""
        if self.simulator is None:
            return None
        return object_source(self.folder, self.simulator.object, self.folder / SESSION_FILE)

    def with_view_done(self, index: int, sha256: dict | None = None, done: bool = True) -> "Session":
        """This session with view ``index`` done, its frames' ``sha256`` (file -> hex); ``done=False``: pending again."""
        views = tuple(replace(v, done=done, sha256=sha256 if done else None) if v.index == index else v for v in self.views)
        return replace(self, views=views)

    def to_dict(self) -> dict:
        """The ``session.json`` manifest."""
        multi = self.plan.passes > 1    # single-pass sessions keep the manifest they had before passes
        plan = {k: v for k, v in asdict(self.plan).items() if k != "passes" or multi}
        data = {"schema": SESSION_SCHEMA, "plan": {**plan, "angles_rad": self.plan.angles().tolist()},
                "pattern": self.pattern.to_dict(),
                "views": [{"index": v.index, "angle_rad": v.angle, "state": "done" if v.done else "pending",
                           "folder": v.folder.name, **({"pass": v.scan_pass} if multi else {}),
                           **({"sha256": dict(v.sha256)} if v.sha256 else {})}
                          for v in self.views],
                "capture": {k: v for k, v in asdict(self.capture).items()
                            if (k != "exposures_us" or v is not None) and (k != "frame_format" or v != "png")}}
        if self.simulator is not None:
            data["simulator"] = {k: ([[list(r) for r in m] for m in v] if k == "pass_motions" else v)
                                 for k, v in asdict(self.simulator).items() if k != "pass_motions" or v is not None}
        if self.hardware is not None:
            data["hardware"] = dict(self.hardware)
        return data

    def save(self) -> None:
        """Write ``session.json`` atomically."""
        atomic_write_json(self.folder / SESSION_FILE, self.to_dict())

    @classmethod
    def load(cls, folder: str | Path) -> "Session":
        """Read ``folder/session.json`` and ``folder/rig.json``, checking every field. Views keep their
        recorded state; their frames are checked by :func:`rangekit.formats.sessions.check.verify_views`.

        Raises
        ------
        ConfigError
            A field is missing, of the wrong type or out of range; the message names session.json, the
            field, what was expected and what was found.
        FileFormatError
            session.json or rig.json is missing or not JSON.
        """
        return _from_dict(read_json(Path(folder) / SESSION_FILE, what="session manifest"), Path(folder))


def load_session(folder: str | Path) -> Session:
    """:meth:`Session.load`."""
    return Session.load(folder)


from rangekit.formats.sessions.fields import (MAX_ANGLE_RAD, MAX_EXPOSURES, MAX_PASSES, MAX_SEED,  # noqa: E402
                                             MAX_VIEWS, MAX_WAIT_S, SHA256_HEX as _SHA256_HEX, error as _error,
                                             fields as _fields, integer as _int, number as _number,
                                             pass_motions as _pass_motions, show as _show)


def _plan(value, path: Path) -> ScanPlan:
    d = _fields(value, path, "plan", ("n_views",), ("step", "start", "angles_rad", "passes"))
    n = _int(d["n_views"], path, "plan.n_views", 1, MAX_VIEWS)
    step = d.get("step")
    step = None if step is None else _number(step, path, "plan.step", -2 * np.pi, 2 * np.pi)
    passes = _int(d.get("passes", 1), path, "plan.passes", 1, MAX_PASSES)   # before passes: one
    if n % passes:
        raise _error(path, "plan.n_views", f"a multiple of plan.passes ({passes})", n)
    return ScanPlan(n_views=n, step=step, start=_number(d.get("start", 0.0), path, "plan.start", -MAX_ANGLE_RAD,
                                                        MAX_ANGLE_RAD), passes=passes)


def _pattern(value, path: Path) -> PatternSpec | LaserSequence:
    if not isinstance(value, dict):
        raise _error(path, "pattern", "a pattern spec (an object with method, width, height, ...)", value)
    try:
        if value.get("method") == LASER_METHOD:
            return LaserSequence.from_dict(value, where=f"{path}: pattern")
        return PatternSpec.from_dict(value, where=f"{path}: pattern")
    except RangekitError as exc:
        raise ConfigError(str(exc)) from None
    except (KeyError, TypeError, ValueError, AttributeError, OverflowError, MemoryError) as exc:
        raise ConfigError(f"{path}: pattern: not a valid pattern spec ({type(exc).__name__}: "
                          f"{_show(str(exc))})") from None


def _capture(value, path: Path) -> CaptureSettings:
    d = _fields(value, path, "capture", (), ("bits", "pattern_delay_s", "turntable_settle_s", "exposures_us",
                                             "frame_format"))
    bits, exps = d.get("bits"), d.get("exposures_us")
    if exps is not None:
        ok = isinstance(exps, list) and 2 <= len(exps) <= MAX_EXPOSURES
        exps = tuple(_int(e, path, f"capture.exposures_us[{i}]", 1, 1_000_000) for i, e in enumerate(exps)) if ok else 0
        if not ok or list(exps) != sorted(set(exps)):
            raise _error(path, "capture.exposures_us", f"2..{MAX_EXPOSURES} increasing exposures in microseconds",
                         d["exposures_us"])
    return CaptureSettings(bits=None if bits is None else _int(bits, path, "capture.bits", 1, 16),
                           pattern_delay_s=_number(d.get("pattern_delay_s", 0.0), path, "capture.pattern_delay_s",
                                                   0.0, MAX_WAIT_S),
                           turntable_settle_s=_number(d.get("turntable_settle_s", 0.0), path,
                                                      "capture.turntable_settle_s", 0.0, MAX_WAIT_S),
                           exposures_us=exps, frame_format=_frame_format(d.get("frame_format", "png"), path))


def _frame_format(value, path: Path) -> str:
    if value not in FRAME_FORMATS:
        raise _error(path, "capture.frame_format", " or ".join(repr(f) for f in FRAME_FORMATS), value)
    return value


def _simulator(value, path: Path, folder: Path, plan: ScanPlan) -> SimulatorSettings:
    d = _fields(value, path, "simulator", ("object", "seed"), ("imaging", "pass_motions"))
    obj = d["object"]
    if not isinstance(obj, str) or not obj or len(obj) > 1024:
        raise _error(path, "simulator.object", "a built-in object name or a mesh file in the session folder", obj)
    object_source(folder, obj, path)
    imaging = d.get("imaging", {})
    if not isinstance(imaging, dict):
        raise _error(path, "simulator.imaging", "an object (the simulator's imaging model)", imaging)
    motions = d.get("pass_motions")
    if motions is not None:
        motions = _pass_motions(motions, path, "simulator.pass_motions", plan.passes)
    return SimulatorSettings(object=obj, seed=_int(d["seed"], path, "simulator.seed", 0, MAX_SEED), imaging=imaging,
                             pass_motions=motions)


def _sha256(value, path: Path, key: str, names: list[str]) -> dict:
    names = sorted(names)
    if not isinstance(value, dict) or sorted(value) != names:
        raise _error(path, key, f"an object with the SHA-256 of each of the {len(names)} frames "
                                f"({names[0]} ... {names[-1]})", value)
    for name, digest in value.items():
        if not (isinstance(digest, str) and len(digest) == 64 and set(digest) <= _SHA256_HEX):
            raise _error(path, f"{key}[{name!r}]", "64 lower-case hex digits (SHA-256)", digest)
    return dict(value)


def _views(value, path: Path, folder: Path, plan: ScanPlan, frame_files: list[str]) -> tuple[SessionView, ...]:
    if not isinstance(value, list) or len(value) != plan.n_views:
        raise _error(path, "views", f"a list of views (index, angle_rad, state), {plan.n_views} as in "
                                    "plan.n_views", value)
    angles, passes = plan.angles(), plan.view_passes()
    views = []
    for i, v in enumerate(value):
        key = f"views[{i}]"
        d = _fields(v, path, key, ("index", "angle_rad", "state"), ("folder", "sha256", "pass"))
        _int(d["index"], path, f"{key}.index", i, i)
        angle = _number(d["angle_rad"], path, f"{key}.angle_rad", -MAX_ANGLE_RAD, MAX_ANGLE_RAD)
        if abs(angle - angles[i]) > 1e-9:
            raise _error(path, f"{key}.angle_rad", f"{shown(angles[i])} (the plan's angle of view {i})", angle)
        if d["state"] not in ("done", "pending"):
            raise _error(path, f"{key}.state", "'done' or 'pending'", d["state"])
        name = view_folder(folder, i).name
        if d.get("folder", name) != name:
            raise _error(path, f"{key}.folder", repr(name), d["folder"])
        scan_pass = int(passes[i])
        if d.get("pass", scan_pass) != scan_pass:
            raise _error(path, f"{key}.pass", f"{scan_pass} (the plan's pass of view {i})", d["pass"])
        done, sha = d["state"] == "done", d.get("sha256")
        if sha is not None:
            if not done:
                raise _error(path, f"{key}.sha256", "none on a pending view", sha)
            sha = _sha256(sha, path, f"{key}.sha256", frame_files)
        views.append(SessionView(i, angle, done, view_folder(folder, i), sha, scan_pass))
    return tuple(views)


def _from_dict(data, folder: Path) -> Session:
    path = folder / SESSION_FILE
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a JSON object (a session manifest), found {type(data).__name__} "
                          f"{_show(data)}")
    if data.get("schema") != SESSION_SCHEMA:
        raise _error(path, "schema", repr(SESSION_SCHEMA), data.get("schema"))
    _fields(data, path, "session manifest", ("schema", "plan", "pattern", "views"),
            ("capture", "simulator", "hardware"))
    plan = _plan(data["plan"], path)
    pattern = _pattern(data["pattern"], path)
    early = _capture(data["capture"], path) if data.get("capture") is not None else None
    files = frame_files(pattern, early and early.exposures_us, early.frame_format if early else "png")
    views = _views(data["views"], path, folder, plan, files)
    simulator = None if data.get("simulator") is None else _simulator(data["simulator"], path, folder, plan)
    hardware = data.get("hardware")
    if hardware is not None:
        d = _fields(hardware, path, "hardware", (), ("rig_file",))
        if not isinstance(d.get("rig_file", ""), str):
            raise _error(path, "hardware.rig_file", "a file name", d["rig_file"])
        if simulator is not None:
            raise ConfigError(f"{path}: expected either simulator or hardware, found both")
    rig = load_rig(folder / RIG_FILE)
    if early is not None:
        capture = early
    else:  # written before capture settings were recorded
        capture = CaptureSettings.from_rig(rig, hardware=hardware is not None)
        bits = simulator.imaging.get("bits") if simulator is not None else None
        if bits is not None:
            capture = replace(capture, bits=_int(bits, path, "simulator.imaging.bits", 1, 16))
    return Session(folder, plan, pattern, rig, capture, views, simulator, hardware)
