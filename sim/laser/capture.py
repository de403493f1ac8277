"""Write one turntable position of a simulated laser-line scanner as a capture folder.

Folder layout (every file written atomically)::

    off.png                 lasers off: ambient light only (8-bit, or 16-bit PNG holding 10-16-bit values;
                            (H, W, 3) RGB for a colour camera, else (H, W))
    laser0.png, laser1.png  laser k on, the others off (one per rig laser, in the rig file's order)
    rig.json                the rig file: cameras (as in coded-light rig files), the turntable, 'lasers'
    capture.json            kind "rangekit.sim.laser_capture/1", turntable_angle_rad, seed, objects,
                            imaging model, laser look, frames (["off", "laser0", ...]), n_lasers
    ground_truth.npz        depth (H, W) camera z in m, NaN where no surface; hit (H, W) bool;
                            T_world_cam (4, 4);
                            per laser k: laser{k}_xyz (H, W, 3) world point (the same frame as the
                            coded-light ground truth's xyz: the rig's world = turntable frame, object posed
                            at the angle) of the lit curve at each pixel it passes through, NaN elsewhere;
                            laser{k}_curve_uv (N, 2) distorted pixel (u, v) of the visible curve's dense
                            samples (<= 0.5 px apart); laser{k}_curve_xyz (N, 3) their world points
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path
from typing import Callable

import numpy as np

from rangekit.errors import SceneError
from rangekit.io import atomic_save_npz, atomic_write_json, write_png
from rangekit.rig.rig_file import save_rig
from rangekit.sim.laser.frames import LaserView
from rangekit.formats.sessions.files import RIG_FILE

__all__ = ["write_laser_capture", "LASER_CAPTURE_KIND"]

LASER_CAPTURE_KIND = "rangekit.sim.laser_capture/1"


def write_laser_capture(view: LaserView, out_dir: str | Path, *, seed: int = 0, info: dict | None = None,
                        progress: Callable[[str], None] | None = None) -> list[Path]:
    """Render the off frame and one frame per laser of ``view``; write the folder. Returns the image
    paths (off first)."""
    if view.depth is None:
        raise SceneError(f"write_laser_capture: the view was built with ambient_scale={view.ambient_scale}; the "
                         "capture's depth truth needs ambient_scale=1")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    say = progress or (lambda msg: None)
    n = len(view.rig.lasers)
    say(f"rendering the laser-off frame and {n} laser frame(s) at {np.degrees(view.angle):g} deg")
    paths = [out / "off.png"]
    write_png(paths[0], view.off())
    truth = {"depth": view.depth, "hit": view.geometry.hit, "T_world_cam": view.camera.T_world_cam}
    for k in range(n):
        frame = view.frame(k)
        if len(frame.curve.uv) == 0:
            say(f"warning: laser {k} ({view.rig.lasers[k].name}) lights nothing the camera sees")
        path = out / f"laser{k}.png"
        write_png(path, frame.image)
        paths.append(path)
        truth[f"laser{k}_xyz"] = frame.xyz
        truth[f"laser{k}_curve_uv"] = frame.curve.uv
        truth[f"laser{k}_curve_xyz"] = frame.curve.xyz
    save_rig(view.rig, out / RIG_FILE)
    atomic_write_json(out / "capture.json", {
        "kind": LASER_CAPTURE_KIND, "turntable_angle_rad": view.angle, "seed": int(seed),
        "objects": list(view.mesh.object_names), "imaging": asdict(view.imaging), "look": asdict(view.look),
        "frames": [p.stem for p in paths], "n_lasers": n, **(info or {})})
    atomic_save_npz(out / "ground_truth.npz", **truth)
    say(f"wrote {len(paths)} image(s), ground_truth.npz and {RIG_FILE} to {out}")
    return paths
