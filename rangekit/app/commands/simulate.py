"""Simulated captures written as folders a real sensor would give, plus exact ground truth: the work
behind ``rangekit sim render`` (projector-camera rig, continuous-wave and pulsed ToF, active stereo).

Each function reports what it renders through ``progress(msg)`` and writes into ``out``.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Callable, Sequence

from rangekit.budget import check_budget
from rangekit.errors import InputError, UsageError
from rangekit.progress import call_progress

__all__ = ["render_projector_capture", "render_laser_capture", "render_laser_stereo_capture", "render_tof_capture",
           "render_stereo_capture", "render_laser_recording", "BYTES_PER_PIXEL"]

#: Peak memory of a simulated capture per camera pixel, bytes (measured as the growth of the peak from a
#: small to a large sensor: ToF 4.6 KB/px, its 3x3 rays per pixel; pulsed ToF 0.54 KB; stereo 1.0 KB per
#: pixel of one camera; projector-camera rig 0.5 KB), checked against the memory budget before rendering.
#: Laser (estimated, not measured): the projector rig's ray cast plus the float32 RGB ambient, noise pool and
#: per-laser xyz truth, 900 bytes. Dots (estimated): as the stereo pair, two casts and two renders of one camera size.
#: Laser stereo (estimated): two laser cameras, each without the per-laser xyz maps, 1600 bytes per pixel of one.
BYTES_PER_PIXEL = {"tof": 5000, "tof-pulsed": 640, "stereo": 1100, "projector": 640, "laser": 900, "dots": 1100,
                   "laser-stereo": 1600}
#: The units ``--object-unit`` reads a mesh file in.


def _check_size(sensor: str, size: tuple[int, int], *, option: str | None = "--size", extra: int = 0,
                where: str = "") -> None:
    w, h = (int(v) for v in size)
    check_budget(w * h * BYTES_PER_PIXEL[sensor] + extra, f"{where}simulating a {w}x{h} {sensor} camera",
                 option=None if option is None else f"{option} {w}x{h}")


def _object_scene(obj: str, object_unit: str = "m"):
    """The scene of ``obj``: a built-in name, or a mesh file whose lengths are in ``object_unit`` ("m" or "mm"),
    its size checked by :data:`rangekit.rig.plausibility.OBJECT_SIZE` (a mesh in millimetres read as metres
    is an object 100 m across around the rig: refused, naming its size and the unit it looks like)."""
    import numpy as np

    from rangekit.errors import SceneError
    from rangekit.rig.plausibility import OBJECT_SIZE, OBJECT_UNITS, UNIT_SCALES, check_length, format_vector
    from rangekit.sim import default_scene
    from rangekit.sim.scene.objects import BUILTIN_OBJECTS, make_object

    if object_unit not in OBJECT_UNITS:
        raise UsageError(f"--object-unit: expected one of {', '.join(OBJECT_UNITS)}, found {object_unit!r}")
    if obj in BUILTIN_OBJECTS:
        if object_unit != "m":
            raise UsageError(f"--object-unit {object_unit}: only for a mesh file; the built-in object {obj!r} is "
                             "in metres")
        return default_scene(obj)
    scale = UNIT_SCALES[object_unit]
    loaded = make_object(obj, scale=scale)
    extent = np.ptp(loaded.vertices, axis=0)
    check_length(float(np.linalg.norm(extent)), OBJECT_SIZE, where=obj, read_as=object_unit, units=OBJECT_UNITS,
                 shown=f"bounding box {format_vector(extent / scale)} {object_unit}",
                 what="object (its bounding-box diagonal)", error=SceneError,
                 fixes={"mm": "use --object-unit mm", "m": "use --object-unit m (the default)"})
    return default_scene(loaded)


def _object_info(obj: str, object_unit: str) -> dict:
    """What capture.json records of the object: its name or file, and its unit when not metres."""
    return {"object": obj, **({"object_unit": object_unit} if object_unit != "m" else {})}


def render_projector_capture(out: str | Path, *, obj: str = "lumpy", patterns: str = "graycode",
                             rig_file: str | Path | None = None, angle: float = 0.0, bits: int = 8, seed: int = 0,
                             noise: bool = True, global_fraction: float | None = None, object_unit: str = "m",
                             progress: Callable | None = None, motion=None, readout_frames: float = 0.0) -> None:
    """Render ``patterns`` on ``obj`` (built-in name or mesh file, in ``object_unit``) at turntable ``angle``
    (radians) on the rig file's rig (default the simulator's), with a ``bits``-bit camera; write the capture
    folder. ``motion``: ``(kind, metres)``, the object moving along the world x axis during the sequence
    (:class:`rangekit.sim.devices.motion.Motion`; a slip comes halfway through it), seen by a rolling shutter whose
    last row is exposed ``readout_frames`` frames after its first (0: a global shutter)."""
    from rangekit.coded.patterns import make_pattern_spec
    from rangekit.rig.rig_file import load_rig
    from rangekit.sim import ImagingModel, SimRig
    from rangekit.sim.writers.capture import write_capture

    imaging = ImagingModel(bits=bits, colour=patterns == "debruijn")
    if not noise:
        imaging = imaging.noiseless()
    if global_fraction is not None:
        imaging = replace(imaging, global_fraction=global_fraction)
    rig = load_rig(rig_file) if rig_file else None
    if rig is not None:
        cam = rig.camera
        _check_size("projector", (cam.width, cam.height), option=None, where=f"{rig_file}: ")
    sim = SimRig(_object_scene(obj, object_unit), rig, imaging=imaging, seed=seed)
    if sim.turntable is not None:
        sim.turntable.rotate_to(angle)
    spec = make_pattern_spec(patterns, sim.projector.resolution)
    moving = None
    if motion is not None:
        from rangekit.sim.devices.motion import Motion

        moving = Motion(motion[0], motion[1], at_frame=spec.n_frames // 2)
    write_capture(sim, spec, out, info=_object_info(obj, object_unit), progress=progress, motion=moving,
                  readout_frames=readout_frames)


def render_laser_capture(out: str | Path, *, obj: str = "lumpy", rig_file: str | Path | None = None,
                         angle: float = 0.0, bits: int = 8, seed: int = 0, noise: bool = True, colour: bool = True,
                         object_unit: str = "m", progress: Callable | None = None) -> None:
    """The laser-off frame and one frame per line laser of ``obj`` (built-in name or mesh file in
    ``object_unit``) at turntable ``angle`` (radians) on the rig file's rig (it must list ``lasers``; default the simulator's rig with
    two Ciclop-like red lasers, :func:`rangekit.sim.laser.rig.laser_rig`), with a ``bits``-bit RGB (or
    mono) camera; write the capture folder (:mod:`rangekit.sim.laser.capture`)."""
    from rangekit.errors import ConfigError
    from rangekit.rig.rig_file import load_rig
    from rangekit.sim import ImagingModel
    from rangekit.sim.laser.frames import LaserView
    from rangekit.sim.laser.capture import write_laser_capture
    from rangekit.sim.laser.rig import laser_rig

    imaging = ImagingModel(bits=bits, colour=colour)
    if not noise:
        imaging = imaging.noiseless()
    if rig_file:
        rig = load_rig(rig_file)
        if not rig.lasers:
            raise ConfigError(f"{rig_file}: lasers: a laser capture needs at least one line laser, found none "
                              "(docs/rig.md, 'lasers')")
        cam = rig.camera
        _check_size("laser", (cam.width, cam.height), option=None, where=f"{rig_file}: ")
    else:
        rig = laser_rig()
    if rig.capture.get("bits") != bits:
        rig = replace(rig, capture={**rig.capture, "bits": bits})
    scene = _object_scene(obj, object_unit)
    call_progress(progress, f"ray casting {rig.camera.width}x{rig.camera.height} camera pixels")
    view = LaserView(scene, rig, angle, imaging=imaging, seed=seed)
    write_laser_capture(view, out, seed=seed, info=_object_info(obj, object_unit), progress=progress)


def render_laser_stereo_capture(out: str | Path, *, obj: str = "lumpy", rig_file: str | Path | None = None,
                                angle: float = 0.0, bits: int = 8, seed: int = 0, noise: bool = True,
                                colour: bool = True, object_unit: str = "m", progress: Callable | None = None) -> None:
    """The laser-off frame and one frame per line laser of ``obj`` (built-in name or mesh file in ``object_unit``)
    at turntable ``angle`` (radians), in both cameras of a two-camera laser rig: the rig file's (two cameras, the
    turntable and the lasers the simulator draws), default :func:`rangekit.sim.laser.stereo.laser_stereo_rig`;
    ``bits``-bit RGB (or mono) cameras; write the capture folder (:mod:`rangekit.sim.laser.stereo`)."""
    from rangekit.errors import ConfigError
    from rangekit.rig.rig_file import load_rig
    from rangekit.sim import ImagingModel
    from rangekit.sim.laser.stereo import LaserStereoView, laser_stereo_rig, write_laser_stereo_capture

    imaging = ImagingModel(bits=bits, colour=colour)
    if not noise:
        imaging = imaging.noiseless()
    if rig_file:
        rig = load_rig(rig_file)
        if len(rig.cameras) < 2 or not rig.lasers or rig.T_world_table is None:
            raise ConfigError(f"{rig_file}: a two-camera laser capture needs two cameras (left, right), at least one "
                              f"line laser and the turntable, found {len(rig.cameras)} camera(s), {len(rig.lasers)} "
                              f"laser(s) and {'a' if rig.T_world_table is not None else 'no'} turntable "
                              "(docs/laser.md, 'Two cameras, no plane calibration')")
        for cam in rig.cameras[:2]:
            _check_size("laser-stereo", (cam.width, cam.height), option=None, where=f"{rig_file}: ")
    else:
        rig = laser_stereo_rig()
    if rig.capture.get("bits") != bits:
        rig = replace(rig, capture={**rig.capture, "bits": bits})
    scene = _object_scene(obj, object_unit)
    call_progress(progress, f"ray casting two cameras' pixels ({rig.cameras[0].width}x{rig.cameras[0].height}, "
                            f"{rig.cameras[1].width}x{rig.cameras[1].height})")
    view = LaserStereoView(scene, rig, angle, imaging=imaging, seed=seed)
    write_laser_stereo_capture(view, out, info=_object_info(obj, object_unit), progress=progress)


def render_tof_capture(out: str | Path, *, near: float, far: float, jitter: float, pulsed: bool = False,
                       size: tuple[int, int] = (320, 240), plan: str = "kinect",
                       frequencies: Sequence[float] | None = None, steps: int | None = None,
                       multipath: tuple[float, float] | None = None, noise: bool = True,
                       seed: int = 0, progress: Callable | None = None) -> None:
    """The panel scene from ``near`` to ``far`` metres seen by a ToF sensor of ``size`` (W, H) pixels (the defaults
    are ``rangekit sim render``'s: :data:`rangekit.cli.sim.TOF_NEAR_M`, ...).

    Continuous wave: the ``plan`` ("kinect" or "luxonis") or ``frequencies`` in Hz with ``steps`` phase
    steps each (default the plan's, or 4); ``multipath`` = (strength, extra round trip in metres).
    Pulsed: round trips with ``jitter`` seconds RMS of timing jitter.
    """
    from rangekit.sim.sensors.tof import (KINECT_V2_PLAN, LUXONIS_PLAN, ToFSensor, render_pulsed, render_tof, tof_camera,
                                  tof_scene, write_pulsed_capture, write_tof_capture)
    from rangekit.tof import FrequencyPlan

    if pulsed:
        _check_size("tof-pulsed", size)
    else:
        try:
            if frequencies:
                freq_plan = FrequencyPlan.uniform(list(frequencies), steps or 4)
            else:
                freq_plan = {"kinect": KINECT_V2_PLAN, "luxonis": LUXONIS_PLAN}[plan]
                if steps:
                    freq_plan = FrequencyPlan.uniform(freq_plan.frequencies, steps)
        except InputError as exc:
            raise UsageError(f"--frequencies-mhz/--steps: {exc}") from None
        # Besides the per-pixel peak: the raw samples, as float64 and as 16-bit images.
        _check_size("tof", size, extra=int(size[0]) * int(size[1]) * 10 * freq_plan.n_samples)
    scene = tof_scene(near, far)
    camera = tof_camera(*size)
    info = {"scene": f"panels {near:g} to {far:g} m"}
    if pulsed:
        call_progress(progress, f"rendering pulsed round trips ({camera.width}x{camera.height}, jitter "
                                f"{jitter * 1e12:g} ps)")
        write_pulsed_capture(render_pulsed(scene, camera=camera, jitter_s=jitter, seed=seed), out, info=info)
        return
    sensor = ToFSensor()
    if multipath:
        sensor = replace(sensor, multipath_strength=multipath[0], multipath_extra_m=multipath[1])
    call_progress(progress, f"rendering {freq_plan.n_samples} raw samples ({freq_plan.describe()}, "
                            f"{camera.width}x{camera.height}, 3x3 rays per pixel)")
    cap = render_tof(scene, freq_plan, camera=camera, sensor=sensor, noise=noise, seed=seed)
    write_tof_capture(cap, out, info=info)


def render_dots_capture(out: str | Path, *, size: tuple[int, int] = (640, 400), seed: int = 0,
                        progress: Callable | None = None) -> None:
    """The white box and sphere seen by the simulated one-camera dot sensor of ``size`` (W, H) pixels, with its
    reference image of the dots on a plane at 1 m (:mod:`rangekit.sim.sensors.dots`)."""
    from rangekit.sim.sensors.dots import dots_rig, render_dots, write_dots_capture
    from rangekit.sim.sensors.stereo import stereo_scene

    _check_size("dots", size)
    rig = dots_rig(*size)
    call_progress(progress, f"rendering the dot sensor's image and reference ({rig.cameras[0].width}x"
                            f"{rig.cameras[0].height})")
    write_dots_capture(render_dots(stereo_scene(), rig, seed=seed), rig, out)


def render_stereo_capture(out: str | Path, *, size: tuple[int, int] = (640, 400), dots: bool = True, seed: int = 0,
                          progress: Callable | None = None) -> None:
    """The white box and sphere seen by the simulated active-stereo pair of ``size`` (W, H) pixels."""
    from rangekit.sim.sensors.stereo import render_stereo, stereo_rig, stereo_scene, write_stereo_capture

    _check_size("stereo", size)
    rig = stereo_rig(*size)
    call_progress(progress, f"rendering the stereo pair ({rig.cameras[0].width}x{rig.cameras[0].height}, "
                            f"dots {'off' if not dots else 'on'})")
    write_stereo_capture(render_stereo(stereo_scene(), rig, dots=dots, seed=seed), rig, out)


def render_laser_recording(out: str | Path, *, board: bool = False, obj: str = "lumpy",
                           rig_file: str | Path | None = None, steps: int = 100, layout: str = "laser:folders",
                           seed: int = 0, noise: bool = True, colour: bool = True,
                           progress: Callable | None = None) -> list[Path]:
    """``rangekit sim render --sensor laser-recording|laser-board``: a laser rig's recording in a laser layout
    (:mod:`rangekit.formats.layouts.laser`) with its truth (:mod:`rangekit.sim.laser.recording`): ``obj`` turned in
    ``steps`` uniform steps over a turn, or (``board``) the calibration board's sweeps on the turntable, one folder
    each. The rig file's rig (it must list ``lasers`` and the turntable), default the simulator's laser rig."""
    from rangekit.errors import ConfigError
    from rangekit.rig.rig_file import load_rig
    from rangekit.sim import ImagingModel
    from rangekit.sim.laser.recording import write_board_recordings, write_scan_recording
    from rangekit.sim.laser.rig import laser_rig

    imaging = ImagingModel(colour=colour)
    if not noise:
        imaging = imaging.noiseless()
    if rig_file:
        rig = load_rig(rig_file)
        if not rig.lasers or rig.T_world_table is None:
            raise ConfigError(f"{rig_file}: a laser recording needs line lasers and the turntable, found "
                              f"{len(rig.lasers)} laser(s) and {'a' if rig.T_world_table is not None else 'no'} "
                              "turntable (docs/rig.md, 'lasers')")
        _check_size("laser", (rig.camera.width, rig.camera.height), option=None, where=f"{rig_file}: ")
    else:
        rig = laser_rig()
    if board:
        return write_board_recordings(out, rig=rig, layout=layout, seed=seed, imaging=imaging, progress=progress)
    return [write_scan_recording(out, [360.0 * k / steps for k in range(steps)], obj=obj, rig=rig, layout=layout,
                                 seed=seed, imaging=imaging, progress=progress)]
