"""A scan from the command line's point of view: check everything, open the devices (the simulator or
the rig file's hardware), acquire, and process with the simulator's truth when there is one.

Processing itself (:mod:`rangekit.app.process`) does not know about the simulator: this module, which
does, builds the evaluator from :mod:`rangekit.sim` and passes it in.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable

from rangekit.app.process import FUSION_METHODS, Evaluator, process_session
from rangekit.coded.patterns import PatternSpec, make_pattern_spec
from rangekit.errors import ConfigError, RangekitError, UsageError
from rangekit.formats.session import CaptureSettings, Session, SimulatorSettings
from rangekit.formats.summary import ProcessResult
from rangekit.rig import Rig, load_rig
from rangekit.rig_checks import validate_rig_for_hardware

__all__ = ["ScanSetup", "SCAN_DEFAULTS", "prepare_scan", "session_evaluator", "process_scan"]

#: Where a simulated session keeps the mesh file of its object.
OBJECT_FOLDER = "object"


@dataclass(frozen=True, eq=False)
class ScanSetup:
    """What :func:`rangekit.app.acquire.acquire` needs for a new or resumed scan, devices opened."""

    folder: Path
    devices: object                     # the rangekit.devices.Rig protocol: camera, projector, turntable
    rig: Rig
    spec: PatternSpec
    n_views: int
    resume: bool
    n_done: int                         # views already done (resume)
    capture: CaptureSettings | None     # None on resume: the session's own
    simulator: SimulatorSettings | None
    hardware: dict | None
    files: dict = field(default_factory=dict)   # files a new session keeps: relative name -> bytes

    def close(self) -> None:
        """Close the hardware devices (the simulator has nothing to close)."""
        if self.hardware is not None:
            self.devices.close()


#: The options of a new scan when the command line does not give them.
SCAN_DEFAULTS = {"rig": "sim", "obj": "lumpy", "n_views": 12, "patterns": "hybrid", "seed": 0}
_OPTION = {"rig": "--rig", "obj": "--object", "n_views": "--views", "patterns": "--patterns", "seed": "--seed"}


def prepare_scan(*, out: str | None = None, resume: str | None = None, rig: str | None = None,
                 obj: str | None = None, n_views: int | None = None, patterns: str | None = None,
                 seed: int | None = None, fusion: str = "poisson") -> ScanSetup:
    """Check the folder, the rig (file or ``"sim"``), the object and the options before anything moves,
    then open the devices. ``resume`` continues the session in that folder with its own settings; an
    option given (not None) must then equal the session's. Options left None take
    :data:`SCAN_DEFAULTS` in a new scan.

    Raises
    ------
    UsageError
        A bad option, a folder that is not new (without ``resume``), or (with ``resume``) an option that
        differs from the session's: the message names the option, the session's value and the given one.
    ConfigError
        A rig file without a projector or devices, a malformed session.json; the message names the
        folder, file or field.
    """
    # Everything is checked before any work starts or anything moves: the folder, the rig, the object.
    if fusion not in FUSION_METHODS:
        raise UsageError(f"--fusion must be one of {', '.join(FUSION_METHODS)}, found {fusion!r}")
    given = {"rig": rig, "obj": obj, "n_views": n_views, "patterns": patterns, "seed": seed}
    session, files = None, {}
    if resume:
        session = Session.load(resume)
        _check_resume_options(session, given)
        rig_file, the_rig, spec = f"{resume}/rig.json", session.rig, session.pattern
        n_views, hardware = len(session.views), session.hardware is not None
    else:
        rig, obj, n_views, patterns, seed = (SCAN_DEFAULTS[k] if v is None else v for k, v in given.items())
        folder = Path(out)
        if (folder / "session.json").exists():
            raise UsageError(f"--out {folder}: already holds a session (session.json); continue it with "
                              f"'rangekit scan --resume {folder}' or choose another folder")
        if folder.exists() and (not folder.is_dir() or any(folder.iterdir())):
            raise UsageError(f"--out {folder}: exists and is not an empty folder; choose a new or empty folder")
        if n_views < 2:
            raise UsageError(f"--views must be at least 2 to register a scan, found {n_views}")
        hardware = rig != "sim"
        rig_file, the_rig, spec = rig, (load_rig(rig) if hardware else None), None
        if hardware:
            validate_rig_for_hardware(the_rig, where=rig)
    if hardware:
        devices, simulator, hw = _open_hardware(the_rig, rig_file), None, {"rig_file": str(rig_file)}
    else:
        devices, simulator = _simulator(session, obj, seed, the_rig)
        the_rig, hw = devices.rig, None
        if session is None and Path(obj).is_file():
            # The session keeps its own copy of the object's mesh, named relative to its folder.
            simulator, files = replace(simulator, object=f"{OBJECT_FOLDER}/{Path(obj).name}"), {
                f"{OBJECT_FOLDER}/{Path(obj).name}": Path(obj).read_bytes()}
    spec = spec or make_pattern_spec(patterns, (the_rig.projector.width, the_rig.projector.height))
    capture = None if session else CaptureSettings.from_rig(the_rig, hardware=hardware)
    n_done = len(session.done_views) if session else 0
    return ScanSetup(Path(resume or out), devices, the_rig, spec, n_views, bool(resume), n_done, capture,
                     simulator, hw, files)


def _check_resume_options(session: Session, given: dict) -> None:
    """UsageError naming the first option given on the command line that differs from the session."""
    sim = session.simulator
    recorded = {"rig": "sim" if sim is not None else (session.hardware or {}).get("rig_file", "rig.json"),
                "obj": sim.object if sim is not None else None, "n_views": len(session.views),
                "patterns": session.pattern.method, "seed": sim.seed if sim is not None else None}
    for key, value in given.items():
        if value is None:
            continue
        same = value == recorded[key]
        if not same and key == "rig" and value != "sim" and recorded["rig"] != "sim":
            same = Path(value).resolve() == Path(recorded["rig"]).resolve()
        if not same and key == "obj" and sim is not None:  # the session's copy of the same mesh file
            source = session.simulator_object
            same = Path(value).is_file() and Path(source).is_file() and Path(value).read_bytes() == Path(
                source).read_bytes()
        if not same:
            have = "none (a hardware session)" if recorded[key] is None else repr(recorded[key])
            raise UsageError(f"{_OPTION[key]} {value!r} differs from the session in {session.folder}, which has "
                             f"{have}; a resumed scan keeps its session's settings: leave {_OPTION[key]} out or "
                             "start a new scan with --out")


def _open_hardware(rig: Rig, where: str):
    from rangekit.drivers import open_rig_devices

    if rig.projector is None:
        raise ConfigError(f"{where}: a scan needs a projector (field 'projector')")
    devices = open_rig_devices(rig, where=where)
    if devices.camera is None or devices.projector is None:
        devices.close()
        raise ConfigError(f"{where}: 'devices' must name a camera (type depthai) and a projector display "
                          "(devices.projector.display)")
    return devices


def _simulator(session: Session | None, obj: str, seed: int, rig: Rig | None):
    """The simulated rig of a new scan (object, seed, default imaging) or of a resumed one (its settings)."""
    from rangekit.sim import ImagingModel, SimRig, default_scene

    if session is not None:
        settings = session.simulator
        obj, seed = session.simulator_object, settings.seed
        try:
            imaging = ImagingModel(**settings.imaging)
        except (RangekitError, TypeError, ValueError) as exc:
            raise ConfigError(f"{session.folder / 'session.json'}: simulator.imaging: expected the simulator's "
                              f"imaging model fields, found {str(exc)[:200]}") from None
        return SimRig(default_scene(obj), rig, imaging=imaging, seed=seed), settings
    # A bad object name or file fails here, before the folder is made.
    imaging = ImagingModel()
    devices = SimRig(default_scene(obj), rig, imaging=imaging, seed=seed)
    return devices, SimulatorSettings(object=obj, seed=seed, imaging=asdict(imaging))


def session_evaluator(session: Session) -> Evaluator | None:
    """The simulator's truth for a simulated session (:func:`rangekit.sim.evaluate.truth_evaluator`);
    None on hardware."""
    if session.simulator is None:
        return None
    from rangekit.sim.evaluate import truth_evaluator

    return truth_evaluator(session.simulator_object, session.rig)


def process_scan(folder: str | Path, *, fusion: str = "poisson", report: bool = True,
                 progress: Callable | None = None) -> ProcessResult:
    """:func:`process_session` with the simulator's truth as evaluator when the session is simulated."""
    return process_session(folder, fusion=fusion, report=report, evaluate=session_evaluator(Session.load(folder)),
                           progress=progress)
