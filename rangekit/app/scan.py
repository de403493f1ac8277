"""A scan from the command line's point of view: check everything, open the devices (the simulator or
the rig file's hardware), acquire, and process with the simulator's truth when there is one.

Processing itself (:mod:`rangekit.app.process`) does not know about the simulator: this module, which
does, builds the evaluator from :mod:`rangekit.sim` and passes it in.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

from rangekit.app.process import FUSION_METHODS, Evaluator, process_session
from rangekit.coded.patterns import PatternSpec, make_pattern_spec
from rangekit.errors import ConfigError, UsageError
from rangekit.formats.session import CaptureSettings, ProcessResult, Session, SimulatorSettings
from rangekit.rig import Rig, load_rig
from rangekit.rig_checks import validate_rig_for_hardware

__all__ = ["ScanSetup", "prepare_scan", "session_evaluator", "process_scan"]


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

    def close(self) -> None:
        """Close the hardware devices (the simulator has nothing to close)."""
        if self.hardware is not None:
            self.devices.close()


def prepare_scan(*, out: str | None = None, resume: str | None = None, rig: str | None = "sim",
                 obj: str = "lumpy", n_views: int = 12, patterns: str = "hybrid", seed: int = 0,
                 fusion: str = "poisson") -> ScanSetup:
    """Check the folder, the rig (file or ``"sim"``), the object and the options before anything moves,
    then open the devices. ``resume`` continues the session in that folder with its own settings.

    Raises
    ------
    ConfigError
        A bad option, a folder that is not new (without ``resume``), a rig file without a projector or
        devices; the message names the folder, file or field.
    """
    # Everything is checked before any work starts or anything moves: the folder, the rig, the object.
    if fusion not in FUSION_METHODS:
        raise UsageError(f"--fusion must be one of {', '.join(FUSION_METHODS)}, found {fusion!r}")
    session = None
    if resume:
        session = Session.load(resume)
        rig_file, the_rig, spec = f"{resume}/rig.json", session.rig, session.pattern
        n_views, hardware = len(session.views), session.hardware is not None
    else:
        folder = Path(out)
        if (folder / "session.json").exists():
            raise UsageError(f"--out {folder}: already holds a session (session.json); continue it with "
                              f"'rangekit scan --resume {folder}' or choose another folder")
        if folder.exists() and (not folder.is_dir() or any(folder.iterdir())):
            raise UsageError(f"--out {folder}: exists and is not an empty folder; choose a new or empty folder")
        if n_views < 2:
            raise UsageError(f"--views must be at least 2 to register a scan, found {n_views}")
        hardware = rig not in (None, "sim")
        rig_file, the_rig, spec = rig, (load_rig(rig) if hardware else None), None
        if hardware:
            validate_rig_for_hardware(the_rig, where=rig)
    if hardware:
        devices, simulator, hw = _open_hardware(the_rig, rig_file), None, {"rig_file": str(rig_file)}
    else:
        devices, simulator = _simulator(session.simulator if session else None, obj, seed, the_rig)
        the_rig, hw = devices.rig, None
    spec = spec or make_pattern_spec(patterns, (the_rig.projector.width, the_rig.projector.height))
    capture = None if session else CaptureSettings.from_rig(the_rig, hardware=hardware)
    n_done = len(session.done_views) if session else 0
    return ScanSetup(Path(resume or out), devices, the_rig, spec, n_views, bool(resume), n_done, capture,
                     simulator, hw)


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


def _simulator(settings: SimulatorSettings | None, obj: str, seed: int, rig: Rig | None):
    """The simulated rig of a new scan (object, seed, default imaging) or of a resumed one (its settings)."""
    from rangekit.sim import ImagingModel, SimRig, default_scene

    if settings is not None:
        obj, seed, imaging = settings.object, settings.seed, ImagingModel(**settings.imaging)
    else:
        imaging = ImagingModel()
        default_scene(obj)  # a bad object name or file fails here, before the folder is made
    devices = SimRig(default_scene(obj), rig, imaging=imaging, seed=seed)
    return devices, SimulatorSettings(object=obj, seed=seed, imaging=asdict(imaging))


def session_evaluator(session: Session) -> Evaluator | None:
    """The simulator's truth for a simulated session (:func:`rangekit.sim.evaluate.truth_evaluator`);
    None on hardware."""
    if session.simulator is None:
        return None
    from rangekit.sim.evaluate import truth_evaluator

    return truth_evaluator(session.simulator.object, session.rig)


def process_scan(folder: str | Path, *, fusion: str = "poisson", report: bool = True,
                 progress: Callable | None = None) -> ProcessResult:
    """:func:`process_session` with the simulator's truth as evaluator when the session is simulated."""
    return process_session(folder, fusion=fusion, report=report, evaluate=session_evaluator(Session.load(folder)),
                           progress=progress)
