"""A scan session's manifest, ``session.json``, as one typed value (schema ``rangekit.session/1``).

A session folder (written by :func:`rangekit.app.acquire.acquire`) holds::

    session.json          this manifest: plan, pattern spec, capture settings, each view's state, and how
                          the views were taken ("simulator": object, seed, imaging; or "hardware": rig file)
    rig.json              the rig file (calibration) the session was taken with
    patterns.json         the PatternSpec
    view_000/000.png ...  one folder per completed view

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
from rangekit.errors import ConfigError, PatternError
from rangekit.io import atomic_write_json, read_json
from rangekit.rig import Rig, load_rig

__all__ = ["SESSION_SCHEMA", "ScanPlan", "CaptureSettings", "SimulatorSettings", "SessionView", "Session",
           "load_session", "view_folder", "ProcessResult"]

SESSION_SCHEMA = "rangekit.session/1"
_FIELDS = ("schema", "plan", "pattern", "views", "capture", "simulator", "hardware")
#: Waits on hardware when the rig file's ``capture`` section does not set them, seconds.
DEFAULT_PATTERN_DELAY_S = 0.1
DEFAULT_TURNTABLE_SETTLE_S = 0.5


@dataclass(frozen=True)
class ScanPlan:
    """What to acquire: ``n_views`` turntable angles ``start + k * step`` (radians)."""

    n_views: int = 12
    step: float | None = None     # radians; default a full turn / n_views
    start: float = 0.0            # radians

    def angles(self) -> np.ndarray:
        """(n_views,) float64 turntable angles, radians."""
        step = self.step if self.step is not None else 2 * np.pi / self.n_views
        return self.start + step * np.arange(self.n_views)


@dataclass(frozen=True)
class CaptureSettings:
    """How the views were captured: the camera's bit depth and the waits (seconds) between steps."""

    bits: int | None = None             # camera ADC bit depth (8, 10, 12 or 16); None: the images' dtype
    pattern_delay_s: float = 0.0        # wait after showing each pattern (projector latency)
    turntable_settle_s: float = 0.0     # wait after each turntable move (vibration)

    @property
    def full_scale(self) -> float | None:
        """The largest pixel value the camera gives, ``2**bits - 1``; None when ``bits`` is unknown."""
        return float((1 << self.bits) - 1) if self.bits else None

    @classmethod
    def from_rig(cls, rig: Rig, *, hardware: bool) -> "CaptureSettings":
        """The rig file's ``capture`` section; waits only on hardware (defaults 0.1 s and 0.5 s)."""
        c = rig.capture
        if not hardware:
            return cls(bits=c.get("bits"))
        return cls(bits=c.get("bits"), pattern_delay_s=float(c.get("pattern_delay_s", DEFAULT_PATTERN_DELAY_S)),
                   turntable_settle_s=float(c.get("turntable_settle_s", DEFAULT_TURNTABLE_SETTLE_S)))


@dataclass(frozen=True)
class SimulatorSettings:
    """A simulated session: the object (built-in name or mesh file), noise seed and imaging model."""

    object: str
    seed: int
    imaging: dict = field(default_factory=dict)   # rangekit.sim.ImagingModel fields


@dataclass(frozen=True)
class SessionView:
    """One view's state; ``done`` only when its folder holds every frame."""

    index: int
    angle: float    # radians
    done: bool
    folder: Path


def view_folder(folder: str | Path, index: int) -> Path:
    """The folder of view ``index`` in a session folder: ``view_NNN``."""
    return Path(folder) / f"view_{index:03d}"


@dataclass(frozen=True, eq=False)
class Session:
    """A session folder's manifest and rig. Build a new one with :meth:`new`, read one with :meth:`load`."""

    folder: Path
    plan: ScanPlan
    pattern: PatternSpec
    rig: Rig
    capture: CaptureSettings
    views: tuple[SessionView, ...]
    simulator: SimulatorSettings | None = None
    hardware: dict | None = None       # {"rig_file": path} on hardware

    @classmethod
    def new(cls, folder: str | Path, plan: ScanPlan, pattern: PatternSpec, rig: Rig, *,
            capture: CaptureSettings | None = None, simulator: SimulatorSettings | None = None,
            hardware: dict | None = None) -> "Session":
        """A session with every view pending; ``capture`` defaults to the rig file's settings."""
        if capture is None:
            capture = CaptureSettings.from_rig(rig, hardware=hardware is not None)
        views = tuple(SessionView(k, float(a), False, view_folder(folder, k)) for k, a in enumerate(plan.angles()))
        return cls(Path(folder), plan, pattern, rig, capture, views, simulator, hardware)

    @property
    def is_simulated(self) -> bool:
        return self.simulator is not None

    @property
    def done_views(self) -> list[SessionView]:
        return [v for v in self.views if v.done]

    def with_view_done(self, index: int) -> "Session":
        views = tuple(replace(v, done=True) if v.index == index else v for v in self.views)
        return replace(self, views=views)

    def to_dict(self) -> dict:
        """The ``session.json`` manifest."""
        data = {"schema": SESSION_SCHEMA, "plan": {**asdict(self.plan), "angles_rad": self.plan.angles().tolist()},
                "pattern": self.pattern.to_dict(),
                "views": [{"index": v.index, "angle_rad": v.angle, "state": "done" if v.done else "pending",
                           "folder": v.folder.name} for v in self.views],
                "capture": asdict(self.capture)}
        if self.simulator is not None:
            data["simulator"] = asdict(self.simulator)
        if self.hardware is not None:
            data["hardware"] = dict(self.hardware)
        return data

    def save(self) -> None:
        """Write ``session.json`` atomically."""
        atomic_write_json(self.folder / "session.json", self.to_dict())

    @classmethod
    def load(cls, folder: str | Path) -> "Session":
        """Read ``folder/session.json`` and ``folder/rig.json``; a view counts as done only if its folder
        is complete. Errors name the file, the field, what was expected and what was found."""
        return _from_dict(read_json(Path(folder) / "session.json", what="session manifest"), Path(folder))


def load_session(folder: str | Path) -> Session:
    """:meth:`Session.load`."""
    return Session.load(folder)


def _error(path: Path, key: str, expected: str, found) -> ConfigError:
    text = repr(found)
    return ConfigError(f"{path}: {key}: expected {expected}, found {text if len(text) <= 80 else text[:77] + '...'}")


def _from_dict(data: dict, folder: Path) -> Session:
    path = folder / "session.json"
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a JSON object (a session manifest), found {type(data).__name__}")
    if data.get("schema") != SESSION_SCHEMA:
        raise ConfigError(f"{path}: schema must be {SESSION_SCHEMA!r}, found {data.get('schema')!r}")
    unknown = [k for k in data if k not in _FIELDS]
    if unknown:
        raise ConfigError(f"{path}: unknown field(s) {', '.join(map(repr, unknown))}; a session manifest has only "
                          f"{', '.join(_FIELDS)}")
    plan_data = data.get("plan")
    try:
        plan = ScanPlan(n_views=int(plan_data["n_views"]), step=plan_data.get("step"),
                        start=float(plan_data.get("start", 0.0)))
    except (KeyError, TypeError, ValueError):
        raise _error(path, "plan", "an object with n_views (and step, start in radians)", plan_data) from None
    try:
        pattern = PatternSpec.from_dict(data["pattern"], where=f"{path}: pattern")
    except KeyError:
        raise _error(path, "pattern", "a pattern spec (method, width, height, ...)", None) from None
    except (PatternError, AttributeError) as exc:
        raise ConfigError(f"{path}: pattern: {exc}") from None
    rig = load_rig(folder / "rig.json")
    simulator = None
    if data.get("simulator") is not None:
        s = data["simulator"]
        try:
            simulator = SimulatorSettings(object=str(s["object"]), seed=int(s["seed"]), imaging=dict(s.get("imaging", {})))
        except (KeyError, TypeError, ValueError):
            raise _error(path, "simulator", "an object with object, seed (and imaging)", s) from None
    hardware = data.get("hardware")
    if hardware is not None and not isinstance(hardware, dict):
        raise _error(path, "hardware", "an object ({\"rig_file\": ...})", hardware)
    if "capture" in data:
        c = data["capture"]
        try:
            capture = CaptureSettings(bits=None if c.get("bits") is None else int(c["bits"]),
                                      pattern_delay_s=float(c.get("pattern_delay_s", 0.0)),
                                      turntable_settle_s=float(c.get("turntable_settle_s", 0.0)))
        except (AttributeError, TypeError, ValueError):
            raise _error(path, "capture", "an object with bits, pattern_delay_s, turntable_settle_s", c) from None
    else:  # written before capture settings were recorded
        capture = CaptureSettings.from_rig(rig, hardware=hardware is not None)
        if simulator is not None and simulator.imaging.get("bits"):
            capture = replace(capture, bits=int(simulator.imaging["bits"]))
    views_data = data.get("views")
    if not isinstance(views_data, list):
        raise _error(path, "views", "a list of views (index, angle_rad, state)", views_data)
    n_frames = pattern.n_frames
    views = []
    for i, v in enumerate(views_data):
        try:
            k, angle, state = int(v["index"]), float(v["angle_rad"]), v["state"]
        except (KeyError, TypeError, ValueError):
            raise _error(path, f"views[{i}]", "an object with index, angle_rad, state", v) from None
        d = view_folder(folder, k)
        complete = (state == "done" and (d / "view.json").exists()
                    and len(list(d.glob("[0-9][0-9][0-9].png"))) == n_frames)
        views.append(SessionView(k, angle, complete, d))
    return Session(folder, plan, pattern, rig, capture, tuple(views), simulator, hardware)


@dataclass(frozen=True, eq=False)
class ProcessResult:
    """What processing a session produced. Distances in metres, times in seconds."""

    folder: Path
    view_names: list[str]
    T_world_view: np.ndarray        # (n, 4, 4) registered poses, world = first view
    n_points: list[int]             # points per view after filtering
    edges: list[dict]               # view graph: i, j, rmse, overlap, accepted, rotation/translation residual
    registration_rmse: float        # joint point-to-plane RMS of the final poses
    mesh: dict                      # vertices, triangles, watertight, area_m2, volume_m3, fusion
    seconds: dict = field(default_factory=dict)   # wall time per stage
    accuracy: dict | None = None    # against the truth when an evaluator was given (the simulator's Accuracy)

    @property
    def mesh_path(self) -> Path:
        return self.folder / "mesh.ply"

    @property
    def mesh_watertight(self) -> bool:
        return bool(self.mesh["watertight"])

    def to_dict(self) -> dict:
        return {"schema": "rangekit.summary/1", "views": self.view_names, "n_points": self.n_points,
                "T_world_view": self.T_world_view.tolist(), "edges": self.edges,
                "registration_rmse_m": self.registration_rmse, "mesh": self.mesh, "seconds": self.seconds,
                "accuracy": self.accuracy}

    def summary_lines(self) -> list[str]:
        """The end-of-run summary, one line per fact, for people."""
        acc = [e for e in self.edges if e["accepted"]]
        rot = [e["rotation_residual_deg"] for e in acc if e.get("rotation_residual_deg") is not None]
        tr = [e["translation_residual_mm"] for e in acc if e.get("translation_residual_mm") is not None]
        m = self.mesh
        lines = [f"views: {len(self.view_names)}, points: {sum(self.n_points):,} "
                 f"({min(self.n_points):,} to {max(self.n_points):,} per view)",
                 f"registration: {len(acc)}/{len(self.edges)} pairs accepted, pair ICP RMSE median "
                 f"{np.median([e['rmse_mm'] for e in acc]):.4f} mm, joint RMS {self.registration_rmse * 1e3:.4f} mm"
                 + (f"; synchronisation residual max {max(rot):.4f} deg, {max(tr):.4f} mm" if rot and tr else ""),
                 f"mesh ({m['fusion']}): {m['vertices']:,} vertices, {m['triangles']:,} triangles, watertight "
                 f"{m['watertight']}, area {m['area_m2'] * 1e4:.1f} cm^2"
                 + (f", volume {m['volume_m3'] * 1e6:.1f} cm^3" if m["volume_m3"] is not None else ""),
                 "time: " + ", ".join(f"{k} {v:.1f} s" for k, v in self.seconds.items())]
        if self.accuracy:
            a = self.accuracy
            lines.append(f"accuracy against the true surface: RMS {a['rms'] * 1e3:.3f} mm "
                         f"({a['rms'] / a['diagonal']:.3%} of the {a['diagonal'] * 1e3:.0f} mm diagonal), 95th "
                         f"percentile {a['p95'] * 1e3:.3f} mm; completeness {a['completeness']:.1%} of the visible "
                         f"surface within {a['tolerance'] * 1e3:g} mm")
            lines.append(f"  ({a['visible_fraction']:.0%} of the object is visible within "
                         f"{a['max_incidence_deg']:g} deg of incidence; the other {a['unobserved_area']:.0%} of the "
                         f"mesh is filled in where no view looked, RMS {a['unobserved_rms'] * 1e3:.2f} mm there)")
        return lines

    def __repr__(self) -> str:
        t = ", ".join(f"{k} {v:.1f} s" for k, v in self.seconds.items())
        return (f"ProcessResult({len(self.n_points)} views, {sum(self.n_points)} points, mesh watertight "
                f"{self.mesh_watertight}; {t})")
