"""``rangekit check`` as a job: open the simulator or the rig file's hardware, run :func:`.check.run_check`,
write the pattern delay into the rig file and the outputs (``check.json``, ``check.png``).

On hardware (``rig_file``) the rig file is rewritten atomically with ``capture.pattern_delay_s`` set (and
``devices.camera.flush_frames``, where the camera's type has that field: a UVC webcam) and every other field as it
was (the JSON is read, those fields changed, written back). On the simulator the
default rig with the measured delay is written to ``OUT/rig.json`` (with ``out``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rangekit.app.check.camera import CameraCheck, check_camera
from rangekit.app.check.steps import CheckResult, run_check
from rangekit.errors import ConfigError
from rangekit.app.check.stats import check_figure
from rangekit.rig.camera_controls import controls_from_capture
from rangekit.io import atomic_write_json, write_png
from rangekit.rig.rig_edits import write_camera_section_fields, write_capture_fields
from rangekit.rig.rig_file import Rig, load_rig, save_rig
from rangekit.formats.sessions.files import RIG_FILE

__all__ = ["check_simulated", "check_hardware", "write_check", "write_pattern_delay", "simulated_check_rig"]


def _full_scale(rig: Rig, image=None) -> float:
    bits = rig.capture.get("bits")
    if bits:
        return float((1 << int(bits)) - 1)
    return 255.0 if image is None or np.asarray(image).dtype == np.uint8 else 65535.0


def simulated_check_rig(sim, delay_s: float) -> Rig:
    """The simulator's rig with the measured ``capture.pattern_delay_s``."""
    from dataclasses import replace

    return replace(sim.rig, capture={**sim.rig.capture, "pattern_delay_s": float(delay_s)})


def check_simulated(sim, *, spec=None, progress=None, rig: Rig | None = None) -> tuple[CheckResult, dict]:
    """Check a :class:`rangekit.sim.SimRig` (its camera controls from ``rig``'s ``capture.camera``; None: the
    simulator's own rig); the object mask is the truth's lit pixels of the objects other than the turntable disc."""
    rig = sim.rig if rig is None else rig
    truth = sim.ground_truth()
    names = truth.object_names
    table = [i for i, n in enumerate(names) if "table" in n or "disc" in n]
    mask = truth.lit & (truth.object_id >= 0) & ~np.isin(truth.object_id, table)
    controls = controls_from_capture(rig.capture, where="simulated rig")
    return run_check(sim, rig, controls, full_scale=float(sim.imaging.max_value), mask=mask, truth=truth,
                     spec=spec, progress=progress)


def check_hardware(rig_file: str, *, progress=None) -> tuple[CheckResult | CameraCheck, dict, Rig]:
    """Check the rig file's devices (opened, checked, closed). Without a projector display the camera alone is
    checked (:mod:`rangekit.app.check.camera`: a :class:`CameraCheck`, images ``{"frame": last frame}``)."""
    from rangekit.drivers import open_rig_devices

    rig = load_rig(rig_file)
    devices = open_rig_devices(rig, where=rig_file, coded_light=False)
    try:
        if devices.camera is None:
            raise ConfigError(f"{rig_file}: devices.camera: no camera to check (a 'sim' camera or none); name the "
                              "camera's driver (rangekit rig init --camera TYPE writes its section)")
        if devices.projector is None:
            result, frame = check_camera(devices.camera, _full_scale(rig))
            return result, {"frame": frame}, rig
        controls = controls_from_capture(rig.capture, where=rig_file)
        result, images = run_check(devices, rig, controls, full_scale=_full_scale(rig), progress=progress)
    finally:
        devices.close()
    return result, images, rig


def write_pattern_delay(rig_file: str | Path, delay_s: float, flush_frames: int | None = None) -> list[str]:
    """Rewrite ``rig_file`` atomically with ``capture.pattern_delay_s`` = ``delay_s`` and, when the camera's type
    has the field, ``devices.camera.flush_frames``; nothing else changed. Returns the fields written, as
    "field value"."""
    from rangekit.rig.checks import CAMERA_SECTION_FIELDS

    rig = write_capture_fields(rig_file, {"pattern_delay_s": float(delay_s)})
    written = [f"capture.pattern_delay_s {float(delay_s):g}"]
    kind = ((rig.devices or {}).get("camera") or {}).get("type")
    if flush_frames is not None and "flush_frames" in CAMERA_SECTION_FIELDS.get(kind, ()):
        write_camera_section_fields(rig_file, {"flush_frames": int(flush_frames)})
        written.append(f"devices.camera.flush_frames {int(flush_frames)}")
    return written


def write_check(out: str | Path, result: CheckResult | CameraCheck, images: dict, full_scale: float,
                rig: Rig | None = None) -> list[str]:
    """Write ``check.json``, ``check.png`` (and ``rig.json`` when ``rig`` is given) into ``out``; returns
    the names written."""
    from rangekit.app.check.steps import MIN_CONFIDENCE

    folder = Path(out)
    folder.mkdir(parents=True, exist_ok=True)
    atomic_write_json(folder / "check.json", result.to_dict())
    if isinstance(result, CameraCheck):
        write_png(folder / "check.png", images["frame"])
        return ["check.json", "check.png"]
    write_png(folder / "check.png", check_figure(images["white"], images["black"], full_scale, images["mask"],
                                                 MIN_CONFIDENCE, result.stats))
    names = ["check.json", "check.png"]
    if rig is not None:
        save_rig(rig, folder / RIG_FILE)
        names.append(RIG_FILE)
    return names
