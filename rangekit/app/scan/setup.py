"""A scan's set-up: every option checked against the folder, the rig and the object before anything moves,
then the devices opened (the simulator, or the rig file's hardware).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Callable

import numpy as np
from rangekit.app.scan.options import LASER_STEPS, SCAN_DEFAULTS, ScanOptions
from rangekit.app.scan.presets import PRESETS, fastest_for, preset_of, preset_spec
from rangekit.coded.patterns import PatternSpec, make_pattern_spec
from rangekit.errors import ConfigError, OptionError, RangekitError
from rangekit.formats.sessions.session import FRAME_FORMATS, CaptureSettings, Session, SimulatorSettings
from rangekit.geometry import R_up_to_z
from rangekit.laser.sequence import LaserSequence
from rangekit.laser.triangulate import check_plane_camera
from rangekit.rig.checks import validate_rig_for_hardware
from rangekit.rig.rig_file import Rig, load_rig
from rangekit.formats.sessions.files import RIG_FILE, SESSION_FILE

__all__ = ["ScanSetup", "OBJECT_FOLDER", "prepare_scan", "check_laser_planes"]

#: Where a simulated session keeps the mesh file of its object.
OBJECT_FOLDER = "object"


@dataclass(frozen=True, eq=False)
class ScanSetup:
    """What :func:`rangekit.app.acquire.acquire.acquire` needs for a new or resumed scan, devices opened."""

    folder: Path
    devices: object                     # the rangekit.rig.devices.RigDevices protocol: camera, projector, turntable
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
    resumed_exposures_us: tuple | None = None   # on resume: the session's own exposures (None: one exposure)

    @property
    def exposures_us(self) -> tuple | None:
        """The exposures every frame is taken at (microseconds; None: the rig's one exposure)."""
        return (self.capture.exposures_us if self.capture is not None else self.resumed_exposures_us) or None

    def close(self) -> None:
        """Close the hardware devices (the simulator has nothing to close)."""
        if self.hardware is not None:
            self.devices.close()


def prepare_scan(options: ScanOptions, progress: Callable | None = None) -> ScanSetup:
    """Check the folder, the rig (file or ``"sim"``), the object and the options before anything moves,
    then open the devices (:class:`ScanOptions`: a new scan's options left None take
    :data:`rangekit.app.scan.options.SCAN_DEFAULTS`; a resumed one's must equal its session's). A laser scan
    takes ``steps`` turntable steps (default :data:`rangekit.app.scan.options.LASER_STEPS`). ``up`` turns a
    mesh file object upright; the session keeps it so. ``passes`` (coded light): that many passes, the object
    turned over between them (on the simulator by a known motion, :mod:`rangekit.sim.scene.passes`; on
    hardware by the user, :func:`rangekit.app.scan.passes.turn_over_prompt`). ``exposures``: the set-up's
    capture takes them (``("auto",)``: from ``rangekit check``'s statistics on the opened devices).

    Raises
    ------
    OptionError
        A folder that is not new (without ``resume``), or (with ``resume``) an option that differs from the
        session's: the message names the option, the session's value and the given one.
    ConfigError
        A rig file without a projector or devices, a laser plane through the camera centre (laser scan),
        a malformed session.json; the message names the folder, file or field.
    """
    # Everything is checked before any work starts or anything moves: the folder, the rig, the object.
    method, rig, obj, up, resume, seed = (options.method, options.rig, options.object, options.up, options.resume,
                                          options.seed)
    rig = None if rig is None else str(rig)
    obj = None if obj is None else str(obj)
    given = {"method": method, "rig": rig, "object": obj, "views": options.turntable_positions,
             "patterns": options.patterns, "seed": options.seed, "passes": options.passes}
    session, files = None, {}
    if resume is not None:
        resume = str(resume)
        session = Session.load(resume)
        _check_resume_options(session, given)
        if options.flipped and session.plan.passes < 2:
            raise OptionError(f"{{flipped}} confirms that the object was turned over between passes, but the session "
                              f"in {resume} has one pass: nothing is turned over; leave {{flipped}} out")
        rig_file, the_rig, spec = f"{resume}/{RIG_FILE}", session.rig, session.pattern
        n_views, hardware, passes = len(session.views), session.hardware is not None, session.plan.passes
        method = "laser" if session.is_laser else "coded"
    else:
        if method == "laser" and given["views"] is None:
            given["views"] = LASER_STEPS
        method, rig, obj, n_views, patterns, seed, passes = (SCAN_DEFAULTS[k] if v is None else v
                                                             for k, v in given.items())
        if options.target_mm is not None:      # checked before anything opens: OptionError when none meets it
            patterns = fastest_for(options.target_mm)
        folder = Path(options.out)
        if (folder / SESSION_FILE).exists():
            raise OptionError(f"{{out}} {folder}: already holds a session ({SESSION_FILE}); continue it with "
                              f"'rangekit scan --resume {folder}' or choose another folder")
        if folder.exists() and (not folder.is_dir() or any(folder.iterdir())):
            raise OptionError(f"{{out}} {folder}: exists and is not an empty folder; choose a new or empty folder")
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
            raise OptionError(f"{{up}} turns a mesh file's object upright; {{object}} {obj!r} is "
                              + ("a hardware scan's real object" if hardware else "a built-in object, already upright"))
    laser = method == "laser"
    if laser and the_rig is not None:
        check_laser_planes(the_rig, where=str(rig_file))
    if hardware:
        devices, simulator, hw = _open_hardware(the_rig, rig_file, laser), None, {"rig_file": str(rig_file)}
    else:
        devices, simulator = _simulator(session, obj, seed, the_rig, laser,
                                        object_file if session is None else None, passes, options.realtime,
                                        options.sim_triggered)
        the_rig, hw = (session.rig if session else _scan_rig(devices.rig, laser, seed, progress)), None
        if session is None and object_file is not None:
            # The session keeps its own copy of the object's mesh, named relative to its folder.
            simulator, files = replace(simulator, object=f"{OBJECT_FOLDER}/{object_file[0]}"), {
                f"{OBJECT_FOLDER}/{object_file[0]}": object_file[1]}
    if spec is None:
        spec = LaserSequence(len(the_rig.lasers)) if laser else _pattern_spec(
            patterns, (the_rig.projector.width, the_rig.projector.height))
    capture = None if session else replace(CaptureSettings.from_rig(the_rig, hardware=hardware or options.realtime),
                                           frame_format=options.frames or ("png" if laser else FRAME_FORMATS[0]))
    n_done = len(session.done_views) if session else 0
    setup = ScanSetup(options.folder, devices, the_rig, spec, n_views, resume is not None, n_done, capture,
                      simulator, hw, files, passes, session.capture.exposures_us if session else None)
    if options.exposures is not None:
        try:
            setup = _with_exposures(setup, tuple(options.exposures), progress)
        except BaseException:
            setup.close()
            raise
    return setup


def _pattern_spec(patterns: str, size: tuple[int, int]) -> PatternSpec:
    """A new coded-light scan's patterns on a ``(width, height)`` projector: a named set
    (:data:`rangekit.app.scan.presets.PRESETS`) or a method with its own options."""
    return preset_spec(patterns, size) if patterns in PRESETS else make_pattern_spec(patterns, size)


def _with_exposures(setup: ScanSetup, given: tuple, progress: Callable | None) -> ScanSetup:
    """The set-up of a new coded-light scan with ``exposures``: those given, increasing, or with ``("auto",)``
    those of ``rangekit check``'s statistics on the devices."""
    from rangekit.app.check.steps import exposures_from_check
    from rangekit.rig.camera_controls import controls_from_capture

    if given == ("auto",):
        full_scale = setup.capture.full_scale or 255.0
        exps = exposures_from_check(setup.devices, setup.rig,
                                    controls_from_capture(setup.rig.capture, where="rig file"), full_scale)
    else:
        exps = tuple(sorted(set(given)))
    if not 2 <= len(exps) <= 8:
        raise OptionError(f"{{exposures}}: expected 2 to 8 different exposures, found {' '.join(map(str, exps))}")
    return replace(setup, capture=replace(setup.capture, exposures_us=tuple(int(e) for e in exps)))


def _check_resume_options(session: Session, given: dict) -> None:
    """OptionError naming the first option given that differs from the session."""
    sim = session.simulator
    recorded = {"method": "laser" if session.is_laser else "coded",
                "rig": "sim" if sim is not None else (session.hardware or {}).get("rig_file", RIG_FILE),
                "object": sim.object if sim is not None else None, "views": session.plan.views_per_pass,
                "passes": session.plan.passes,
                "patterns": session.pattern.method if given.get("patterns") not in PRESETS
                else preset_of(session.pattern), "seed": sim.seed if sim is not None else None}
    for key, value in given.items():
        if value is None:
            continue
        same = value == recorded[key]
        if not same and key == "rig" and value != "sim" and recorded["rig"] != "sim":
            same = Path(value).resolve() == Path(recorded["rig"]).resolve()
        if not same and key == "object" and sim is not None:  # the session's copy of the same mesh file
            source = session.simulator_object
            same = Path(value).is_file() and Path(source).is_file() and Path(value).read_bytes() == Path(
                source).read_bytes()
        if not same:
            have = "none (a hardware session)" if recorded[key] is None else repr(recorded[key])
            name = "{steps}" if key == "views" and session.is_laser else f"{{{key}}}"
            raise OptionError(f"{name} {value!r} differs from the session in {session.folder}, which has "
                              f"{have}; a resumed scan keeps its session's settings: leave {name} out or "
                              "start a new scan with {out}")


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
        raise OptionError(f"{{up}}: expected a non-zero direction X Y Z, found {up!r}")
    if u is None or np.allclose(u / np.linalg.norm(u), [0.0, 0.0, 1.0]):
        return path.name, path.read_bytes()
    from rangekit.formats.meshes import load_mesh
    from rangekit.formats.ply_write import mesh_ply_bytes
    from rangekit.surface.mesh import TriangleMesh

    R = R_up_to_z(u)
    mesh = load_mesh(path)
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


def _default_sim_rig() -> Rig:
    from rangekit.sim.devices.sim_rig import default_rig

    return default_rig()


def _simulator(session: Session | None, obj: str, seed: int, rig: Rig | None, laser: bool = False,
               object_file: tuple[str, bytes] | None = None, passes: int = 1, realtime: bool = False,
               triggered: bool = False):
    """The simulated rig of a new scan (object, seed, default imaging) or of a resumed one (its settings).
    A laser scan renders the line lasers of :func:`rangekit.sim.laser.rig.laser_rig` (the simulator's truth;
    the session's rig holds the calibrated planes). ``object_file``: (name, bytes) the session will keep of
    a mesh file, which the simulator then reads (turned upright by ``--up``). ``passes`` > 1: the object
    is turned over between passes (:func:`rangekit.sim.scene.passes.pass_motions`, recorded for the truth).
    ``realtime``: the devices keep real time (:mod:`rangekit.sim.devices.realtime`), waiting the session's (or
    the rig file's) pattern delay. ``triggered`` (a new scan): the simulator's rig says ``capture.trigger``
    "projector", its camera triggered by the projector's VSYNC (:mod:`rangekit.sim.devices.trigger`); a resumed
    session's rig says it itself."""
    import tempfile

    from rangekit.sim import ImagingModel, SimRig, default_scene
    from rangekit.sim.laser.rig import laser_rig

    options = {"light": "laser"} if laser else {}
    if triggered and rig is None:
        rig = _default_sim_rig()
        rig = replace(rig, capture={**rig.capture, "trigger": "projector"})
    if realtime:
        from rangekit.rig.checks import camera_triggered
        from rangekit.sim.devices.realtime import realtime_options

        capture = session.capture if session is not None else None
        delay = capture.pattern_delay_s if capture is not None else CaptureSettings.from_rig(
            rig if rig is not None else _default_sim_rig(), hardware=True).pattern_delay_s
        options.update(realtime_options(delay, triggered=rig is not None and camera_triggered(rig.capture)))
    if laser:
        rig = laser_rig(rig if rig is not None and not rig.lasers else None)
    if session is not None:
        settings = session.simulator
        obj, seed = session.simulator_object, settings.seed
        try:
            imaging = ImagingModel(**settings.imaging)
        except (RangekitError, TypeError, ValueError) as exc:
            raise ConfigError(f"{session.folder / SESSION_FILE}: simulator.imaging: expected the simulator's "
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
