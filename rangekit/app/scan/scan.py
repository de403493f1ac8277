"""A scan from the command line's point of view: check everything, open the devices (the simulator or
the rig file's hardware), acquire, and process with the simulator's truth when there is one.

Processing itself (:mod:`rangekit.app.process.process`) does not know about the simulator: this module, which
does, builds the evaluator from :mod:`rangekit.sim` and passes it in.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np
from rangekit.app.process.evaluate import Evaluator
from rangekit.app.process.options import FUSION_METHODS, ProcessOptions
from rangekit.app.process.process import process_session
from rangekit.coded.patterns import PatternSpec, make_pattern_spec
from rangekit.errors import ConfigError, RangekitError, UsageError
from rangekit.geometry import R_up_to_z
from rangekit.formats.sessions.session import CaptureSettings, Session, SimulatorSettings
from rangekit.formats.sessions.summary import ProcessResult
from rangekit.laser.sequence import LaserSequence
from rangekit.laser.triangulate import check_plane_camera
from rangekit.rig.rig_file import Rig, load_rig
from rangekit.rig.checks import validate_rig_for_hardware

__all__ = ["ScanSetup", "SCAN_DEFAULTS", "prepare_scan", "check_laser_planes", "session_evaluator", "process", "process_scan"]

#: Where a simulated session keeps the mesh file of its object.
OBJECT_FOLDER = "object"


@dataclass(frozen=True, eq=False)
class ScanSetup:
    """What :func:`rangekit.app.acquire.acquire.acquire` needs for a new or resumed scan, devices opened."""

    folder: Path
    devices: object                     # the rangekit.rig.devices.Rig protocol: camera, projector, turntable
    rig: Rig
    spec: PatternSpec | LaserSequence   # coded light: the patterns; laser: off + one frame per laser
    n_views: int                        # turntable positions in all (over a full turn in each pass)
    resume: bool
    n_done: int                         # views already done (resume)
    capture: CaptureSettings | None     # None on resume: the session's own
    simulator: SimulatorSettings | None
    hardware: dict | None
    files: dict = field(default_factory=dict)   # files a new session keeps: relative name -> bytes
    passes: int = 1                     # turntable passes, the object turned over between them

    def close(self) -> None:
        """Close the hardware devices (the simulator has nothing to close)."""
        if self.hardware is not None:
            self.devices.close()


#: Scan methods: coded light (projector patterns, views registered) and laser lines (profiles at small
#: turntable steps, placed by the turntable angle).
SCAN_METHODS = ("coded", "laser")
#: The options of a new scan when the command line does not give them.
SCAN_DEFAULTS = {"method": "coded", "rig": "sim", "obj": "lumpy", "n_views": 12, "patterns": "hybrid", "seed": 0,
                 "passes": 1}
#: Turntable steps of a laser scan over a full turn (0.9 degrees each).
LASER_STEPS = 400
_OPTION = {"method": "--method", "rig": "--rig", "obj": "--object", "n_views": "--views", "patterns": "--patterns",
           "seed": "--seed", "passes": "--passes"}


def prepare_scan(*, out: str | None = None, resume: str | None = None, rig: str | None = None,
                 obj: str | None = None, n_views: int | None = None, patterns: str | None = None,
                 seed: int | None = None, fusion: str = "poisson", method: str | None = None,
                 up: tuple[float, float, float] | None = None, progress: Callable | None = None,
                 passes: int | None = None) -> ScanSetup:
    """Check the folder, the rig (file or ``"sim"``), the object and the options before anything moves,
    then open the devices. ``resume`` continues the session in that folder with its own settings; an
    option given (not None) must then equal the session's. Options left None take
    :data:`SCAN_DEFAULTS` in a new scan. ``method`` "laser" scans with the rig's line lasers at
    ``n_views`` turntable steps (default :data:`LASER_STEPS`); ``patterns`` is then not used. ``up``: the
    direction of a mesh file's object that stands up on the turntable (``(0, 1, 0)`` for Stanford meshes);
    the session keeps the object turned upright. ``passes`` (coded light): that many passes of ``n_views``
    views each, the object turned over between them (on the simulator by a known motion,
    :mod:`rangekit.sim.scene.passes`; on hardware by the user, :func:`rangekit.app.scan.passes.turn_over_prompt`).

    Raises
    ------
    UsageError
        A bad option, a folder that is not new (without ``resume``), or (with ``resume``) an option that
        differs from the session's: the message names the option, the session's value and the given one.
    ConfigError
        A rig file without a projector or devices, a laser plane through the camera centre (laser scan),
        a malformed session.json; the message names the folder, file or field.
    """
    # Everything is checked before any work starts or anything moves: the folder, the rig, the object.
    if fusion not in FUSION_METHODS:
        raise UsageError(f"--fusion must be one of {', '.join(FUSION_METHODS)}, found {fusion!r}")
    if method is not None and method not in SCAN_METHODS:
        raise UsageError(f"--method must be one of {', '.join(SCAN_METHODS)}, found {method!r}")
    if method == "laser" and patterns is not None:
        raise UsageError("--patterns: a laser scan projects no patterns; leave --patterns out with --method laser")
    if method == "laser" and passes not in (None, 1):
        raise UsageError(f"--passes: a laser scan takes one pass, found {passes}; leave --passes out with --method laser")
    given = {"method": method, "rig": rig, "obj": obj, "n_views": n_views, "patterns": patterns, "seed": seed,
             "passes": passes}
    session, files = None, {}
    if resume and up is not None:
        raise UsageError("--up: a resumed scan keeps its session's object as it stands; leave --up out")
    if resume:
        session = Session.load(resume)
        _check_resume_options(session, given)
        rig_file, the_rig, spec = f"{resume}/rig.json", session.rig, session.pattern
        n_views, hardware, passes = len(session.views), session.hardware is not None, session.plan.passes
        method = "laser" if session.is_laser else "coded"
    else:
        if method == "laser" and n_views is None:
            given["n_views"] = LASER_STEPS
        method, rig, obj, n_views, patterns, seed, passes = (SCAN_DEFAULTS[k] if v is None else v
                                                             for k, v in given.items())
        folder = Path(out)
        if (folder / "session.json").exists():
            raise UsageError(f"--out {folder}: already holds a session (session.json); continue it with "
                              f"'rangekit scan --resume {folder}' or choose another folder")
        if folder.exists() and (not folder.is_dir() or any(folder.iterdir())):
            raise UsageError(f"--out {folder}: exists and is not an empty folder; choose a new or empty folder")
        if n_views < 2:
            raise UsageError(f"--views must be at least 2 to register a scan, found {n_views}")
        n_views *= passes
        hardware = rig != "sim"
        rig_file, the_rig, spec = rig, (load_rig(rig) if hardware else None), None
        if hardware:
            validate_rig_for_hardware(the_rig, where=rig)
            if method == "laser" and not the_rig.lasers:
                raise ConfigError(f"{rig}: a laser scan needs the rig file's 'lasers' (calibrate them with "
                                  "'rangekit calibrate --lasers')")
        object_file = None if hardware or not Path(obj).is_file() else _object_bytes(obj, up)
        if up is not None and object_file is None:
            raise UsageError(f"--up turns a mesh file's object upright; --object {obj!r} is "
                             + ("a hardware scan's real object" if hardware else "a built-in object, already upright"))
    laser = method == "laser"
    if laser and the_rig is not None:
        check_laser_planes(the_rig, where=str(rig_file))
    if hardware:
        devices, simulator, hw = _open_hardware(the_rig, rig_file, laser), None, {"rig_file": str(rig_file)}
    else:
        devices, simulator = _simulator(session, obj, seed, the_rig, laser,
                                        object_file if session is None else None, passes)
        the_rig, hw = (session.rig if session else _scan_rig(devices.rig, laser, seed, progress)), None
        if session is None and object_file is not None:
            # The session keeps its own copy of the object's mesh, named relative to its folder.
            simulator, files = replace(simulator, object=f"{OBJECT_FOLDER}/{object_file[0]}"), {
                f"{OBJECT_FOLDER}/{object_file[0]}": object_file[1]}
    if spec is None:
        spec = LaserSequence(len(the_rig.lasers)) if laser else make_pattern_spec(
            patterns, (the_rig.projector.width, the_rig.projector.height))
    capture = None if session else CaptureSettings.from_rig(the_rig, hardware=hardware)
    n_done = len(session.done_views) if session else 0
    return ScanSetup(Path(resume or out), devices, the_rig, spec, n_views, bool(resume), n_done, capture,
                     simulator, hw, files, passes)


def _check_resume_options(session: Session, given: dict) -> None:
    """UsageError naming the first option given on the command line that differs from the session."""
    sim = session.simulator
    recorded = {"method": "laser" if session.is_laser else "coded", "rig": "sim" if sim is not None else (session.hardware or {}).get("rig_file", "rig.json"),
                "obj": sim.object if sim is not None else None, "n_views": session.plan.views_per_pass,
                "passes": session.plan.passes,
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


def check_laser_planes(rig: Rig, *, where: str) -> None:
    """Refuse a rig whose laser plane passes (nearly) through the camera centre, before any frame is taken:
    every camera ray then meets the plane at the centre itself and nothing can be triangulated (see
    :func:`rangekit.laser.triangulate.check_plane_camera`). ConfigError naming ``where`` (the rig file) and
    the laser."""
    for i, laser in enumerate(rig.lasers):
        check_plane_camera(laser.plane, rig.camera, f"{where}: lasers[{i}] ({laser.name!r})")


def _open_hardware(rig: Rig, where: str, laser: bool = False):
    from rangekit.drivers import open_rig_devices

    if rig.projector is None and not laser:
        raise ConfigError(f"{where}: a scan needs a projector (field 'projector')")
    devices = open_rig_devices(rig, where=where)
    if laser and (devices.camera is None or devices.turntable is None):
        devices.close()
        raise ConfigError(f"{where}: a laser scan needs 'devices' to name a camera (type depthai) and the turntable "
                          "board that switches the lasers (devices.turntable)")
    if not laser and (devices.camera is None or devices.projector is None):
        devices.close()
        raise ConfigError(f"{where}: 'devices' must name a camera (type depthai) and a projector display "
                          "(devices.projector.display)")
    return devices


def _object_bytes(obj: str, up) -> tuple[str, bytes]:
    """The file name and bytes a new session keeps of a mesh file ``obj``: the file itself, or (``up`` given
    and not +z) the mesh turned so that ``up`` points up, as binary PLY (``NAME_upright.ply``)."""
    path = Path(obj)
    u = None if up is None else np.asarray(up, dtype=np.float64)
    if u is not None and (u.shape != (3,) or not np.all(np.isfinite(u)) or np.linalg.norm(u) == 0):
        raise UsageError(f"--up: expected a non-zero direction X Y Z, found {up!r}")
    if u is None or np.allclose(u / np.linalg.norm(u), [0.0, 0.0, 1.0]):
        return path.name, path.read_bytes()
    from rangekit.formats.meshes import load_mesh_file
    from rangekit.formats.ply_write import mesh_ply_bytes
    from rangekit.surface.mesh import TriangleMesh

    R = R_up_to_z(u)
    mesh = load_mesh_file(path)
    return f"{path.stem}_upright.ply", mesh_ply_bytes(TriangleMesh(mesh.vertices @ R.T, mesh.triangles,
                                                                   mesh.vertex_colours))


def _scan_rig(true_rig: Rig, laser: bool, seed: int, progress: Callable | None = None) -> Rig:
    """The rig a new simulated session records: the simulator's own for coded light; for a laser scan, its
    laser planes as calibrated from 10 simulated board poses (seeded by ``seed``; board poses by PnP with
    the rig's camera: :func:`rangekit.app.laser.calibration.calibrate_lasers`), as a user's scan would use
    them, so the scan's accuracy includes the calibration's error."""
    if not laser:
        return true_rig
    from rangekit.app.laser.calibration import calibrate_lasers

    from rangekit.progress import call_progress

    cal = calibrate_lasers(true_rig, n_poses=10, seed=seed, camera=true_rig.camera)
    for line in cal.summary_lines():
        call_progress(progress, line)
    return cal.rig


def _simulator(session: Session | None, obj: str, seed: int, rig: Rig | None, laser: bool = False,
               object_file: tuple[str, bytes] | None = None, passes: int = 1):
    """The simulated rig of a new scan (object, seed, default imaging) or of a resumed one (its settings).
    A laser scan renders the line lasers of :func:`rangekit.sim.laser.rig.laser_rig` (the simulator's truth;
    the session's rig holds the calibrated planes). ``object_file``: (name, bytes) the session will keep of
    a mesh file, which the simulator then reads (turned upright by ``--up``). ``passes`` > 1: the object
    is turned over between passes (:func:`rangekit.sim.scene.passes.pass_motions`, recorded for the truth)."""
    import tempfile

    from rangekit.sim import ImagingModel, SimRig, default_scene
    from rangekit.sim.laser.rig import laser_rig

    options = {"light": "laser"} if laser else {}
    if laser:
        rig = laser_rig(rig if rig is not None and not rig.lasers else None)
    if session is not None:
        settings = session.simulator
        obj, seed = session.simulator_object, settings.seed
        try:
            imaging = ImagingModel(**settings.imaging)
        except (RangekitError, TypeError, ValueError) as exc:
            raise ConfigError(f"{session.folder / 'session.json'}: simulator.imaging: expected the simulator's "
                              f"imaging model fields, found {str(exc)[:200]}") from None
        return SimRig(default_scene(obj), rig, imaging=imaging, seed=seed, pass_motions=settings.pass_motions,
                      **options), settings
    # A bad object name or file fails here, before the folder is made.
    imaging = ImagingModel()
    if object_file is not None and object_file[0] != Path(obj).name:   # turned upright by --up
        with tempfile.TemporaryDirectory() as tmp:
            (Path(tmp) / object_file[0]).write_bytes(object_file[1])
            scene = default_scene(str(Path(tmp) / object_file[0]))
    else:
        scene = default_scene(obj)
    motions = None
    if passes > 1:
        from rangekit.sim.devices.sim_rig import default_rig
        from rangekit.sim.scene.passes import pass_motions

        motions = pass_motions(scene, rig if rig is not None else default_rig(), passes)
    devices = SimRig(scene, rig, imaging=imaging, seed=seed, pass_motions=motions, **options)
    return devices, SimulatorSettings(object=obj, seed=seed, imaging=asdict(imaging), pass_motions=None if motions is None
                                      else tuple(tuple(map(tuple, m.tolist())) for m in motions))


def session_evaluator(session: Session) -> Evaluator | None:
    """The simulator's truth for a simulated session (:func:`rangekit.sim.truth.evaluate.truth_evaluator`);
    None on hardware."""
    if session.simulator is None:
        return None
    from rangekit.sim.truth.evaluate import truth_evaluator

    motions = session.simulator.pass_motions    # the truth of a multi-pass scan: how the object was turned over
    return truth_evaluator(session.simulator_object, session.rig, light="laser" if session.is_laser else "projector",
                           **({"pass_motions": np.array(motions)} if motions is not None else {}))


def process(session: Session | str | Path, options: ProcessOptions | None = None, *,
            on_event=None, map_pairs=None) -> ProcessResult:
    """Process a session (loaded, or its folder) as ``rangekit process`` does: :func:`process_session` with the
    simulator's truth as evaluator when the session is simulated and ``options.truth`` (the session loaded once
    and handed on). ``on_event``: see :mod:`rangekit.app.events`."""
    from rangekit.app.events import failures_announced

    options = options or ProcessOptions()
    with failures_announced(on_event):
        if not isinstance(session, Session):
            if not (Path(session) / "session.json").is_file():
                raise ConfigError(f"{session}: not a session folder (no session.json)")
            session = Session.load(session)
        evaluate = session_evaluator(session) if options.truth else None
    return process_session(session, options, evaluate=evaluate, on_event=on_event, map_pairs=map_pairs)


def process_scan(folder: str | Path, *, fusion: str = "poisson", report: bool = True,
                 progress: Callable | None = None, map_pairs=None) -> ProcessResult:
    """:func:`process` with the command line's ``progress`` (:class:`rangekit.progress.Console`) as subscriber."""
    from rangekit.app.events import progress_subscriber

    return process(folder, ProcessOptions(fusion=fusion, report=report), on_event=progress_subscriber(progress),
                   map_pairs=map_pairs)
