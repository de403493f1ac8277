"""Simulated captures written as folders a real sensor would give, plus exact ground truth: the work
behind ``rangekit sim render`` (projector-camera rig, continuous-wave and pulsed ToF, active stereo).

Each function reports what it renders through ``progress(msg)`` and writes into ``out``.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Callable, Sequence

from rangekit.progress import call_progress

__all__ = ["render_projector_capture", "render_tof_capture", "render_stereo_capture"]


def render_projector_capture(out: str | Path, *, obj: str = "lumpy", patterns: str = "graycode",
                             rig_file: str | Path | None = None, angle: float = 0.0, bits: int = 8, seed: int = 0,
                             noise: bool = True, global_fraction: float | None = None,
                             progress: Callable | None = None) -> None:
    """Render ``patterns`` on ``obj`` (built-in name or mesh file) at turntable ``angle`` (radians) on the
    rig file's rig (default the simulator's), with a ``bits``-bit camera; write the capture folder."""
    from rangekit.coded.patterns import make_pattern_spec
    from rangekit.rig import load_rig
    from rangekit.sim import ImagingModel, SimRig, default_scene
    from rangekit.sim.capture import write_capture

    imaging = ImagingModel(bits=bits, colour=patterns == "debruijn")
    if not noise:
        imaging = imaging.noiseless()
    if global_fraction is not None:
        imaging = replace(imaging, global_fraction=global_fraction)
    rig = load_rig(rig_file) if rig_file else None
    sim = SimRig(default_scene(obj), rig, imaging=imaging, seed=seed)
    if sim.turntable is not None:
        sim.turntable.rotate_to(angle)
    spec = make_pattern_spec(patterns, sim.projector.resolution)
    write_capture(sim, spec, out, info={"object": obj}, progress=progress)


def render_tof_capture(out: str | Path, *, pulsed: bool = False, near: float = 0.5, far: float = 15.0,
                       size: tuple[int, int] = (320, 240), plan: str = "kinect",
                       frequencies: Sequence[float] | None = None, steps: int | None = None,
                       multipath: tuple[float, float] | None = None, jitter: float = 50e-12, noise: bool = True,
                       seed: int = 0, progress: Callable | None = None) -> None:
    """The panel scene from ``near`` to ``far`` metres seen by a ToF sensor of ``size`` (W, H) pixels.

    Continuous wave: the ``plan`` ("kinect" or "luxonis") or ``frequencies`` in Hz with ``steps`` phase
    steps each (default the plan's, or 4); ``multipath`` = (strength, extra round trip in metres).
    Pulsed: round trips with ``jitter`` seconds RMS of timing jitter.
    """
    from rangekit.sim.tof import (KINECT_V2_PLAN, LUXONIS_PLAN, ToFSensor, render_pulsed, render_tof, tof_camera,
                                  tof_scene, write_pulsed_capture, write_tof_capture)
    from rangekit.tof import FrequencyPlan

    scene = tof_scene(near, far)
    camera = tof_camera(*size)
    info = {"scene": f"panels {near:g} to {far:g} m"}
    if pulsed:
        call_progress(progress, f"rendering pulsed round trips ({camera.width}x{camera.height}, jitter "
                                f"{jitter * 1e12:g} ps)")
        write_pulsed_capture(render_pulsed(scene, camera=camera, jitter_s=jitter, seed=seed), out, info=info)
        return
    if frequencies:
        freq_plan = FrequencyPlan.uniform(list(frequencies), steps or 4)
    else:
        freq_plan = {"kinect": KINECT_V2_PLAN, "luxonis": LUXONIS_PLAN}[plan]
        if steps:
            freq_plan = FrequencyPlan.uniform(freq_plan.frequencies, steps)
    sensor = ToFSensor()
    if multipath:
        sensor = replace(sensor, multipath_strength=multipath[0], multipath_extra_m=multipath[1])
    call_progress(progress, f"rendering {freq_plan.n_samples} raw samples ({freq_plan.describe()}, "
                            f"{camera.width}x{camera.height}, 3x3 rays per pixel)")
    cap = render_tof(scene, freq_plan, camera=camera, sensor=sensor, noise=noise, seed=seed)
    write_tof_capture(cap, out, info=info)


def render_stereo_capture(out: str | Path, *, size: tuple[int, int] = (640, 400), dots: bool = True, seed: int = 0,
                          progress: Callable | None = None) -> None:
    """The white box and sphere seen by the simulated active-stereo pair of ``size`` (W, H) pixels."""
    from rangekit.sim.stereo import render_stereo, stereo_rig, stereo_scene, write_stereo_capture

    rig = stereo_rig(*size)
    call_progress(progress, f"rendering the stereo pair ({rig.cameras[0].width}x{rig.cameras[0].height}, "
                            f"dots {'off' if not dots else 'on'})")
    write_stereo_capture(render_stereo(stereo_scene(), rig, dots=dots, seed=seed), rig, out)
