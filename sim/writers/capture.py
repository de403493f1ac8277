"""Write a simulated capture folder: the images a real rig would record, plus the exact truth.

Folder layout (every file written atomically)::

    000.png, 001.png, ...   captures in projection order (8-bit, or 16-bit PNG holding 10-16-bit values)
    patterns.json           the PatternSpec that was projected (frame names in order)
    rig.json                the rig file (true calibration of the simulated rig)
    capture.json            what was simulated: object, turntable angle, seed, imaging model
    ground_truth.npz        depth (H, W) camera z in m; xyz (H, W, 3) world points in m; normals (H, W, 3)
                            world unit normals; proj_col, proj_row (H, W) projector pixels; valid (H, W)
                            bool (seen and lit); hit (H, W) bool (seen); T_world_cam (4, 4).
                            NaN / False where undefined.
    preview.png             white capture, depth, projector column and validity, side by side
"""

from __future__ import annotations

from dataclasses import asdict
from pathlib import Path
from typing import Callable

import cv2
import numpy as np

from rangekit.colour import colourise
from rangekit.io import atomic_save_npz, atomic_write_json, write_png
from rangekit.coded.patterns import PatternSpec
from rangekit.rig.rig_file import save_rig
from rangekit.sim.devices.sim_rig import SimRig
from rangekit.sim.scene.raycast import ViewGeometry
from rangekit.formats.sessions.files import PATTERNS_FILE, RIG_FILE

__all__ = ["write_capture", "preview_image"]


def _colourise(values: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """(H, W) float -> (H, W, 3) uint8 RGB turbo colour map, black where invalid."""
    out = np.zeros(values.shape + (3,), np.uint8)
    if np.any(valid):
        lo, hi = np.percentile(values[valid], [1, 99])
        out[valid] = colourise(values[valid], lo, max(hi, lo), cmap="turbo")
    return out


def preview_image(white: np.ndarray, truth: ViewGeometry, *, width: int = 480) -> np.ndarray:
    """A (h, 4 * width, 3) uint8 RGB strip: white capture, depth, projector column, valid mask."""
    img = white.astype(np.float32) / (255.0 if white.dtype == np.uint8 else float(white.max() or 1))
    img = np.clip(img * 255, 0, 255).astype(np.uint8)
    if img.ndim == 2:
        img = np.repeat(img[:, :, None], 3, axis=2)
    panels = [img, _colourise(truth.depth, truth.hit), _colourise(truth.proj_col, truth.lit),
              np.repeat((truth.lit * 255).astype(np.uint8)[:, :, None], 3, axis=2)]
    H, W = truth.hit.shape
    h = int(round(H * width / W))
    return np.hstack([cv2.resize(p, (width, h), interpolation=cv2.INTER_AREA) for p in panels])


def write_capture(sim: SimRig, spec: PatternSpec, out_dir: str | Path, *, info: dict | None = None,
                  progress: Callable[[str], None] | None = None, motion=None, readout_frames: float = 0.0) -> list[Path]:
    """Project every frame of ``spec`` on ``sim`` at its current state and write the capture folder.

    ``motion``: the object moves during the sequence (:class:`rangekit.sim.devices.motion.Motion`; recorded in
    capture.json with each frame's offset); the ground truth is the object where it was at the first frame.
    ``readout_frames``: with ``motion``, a rolling shutter whose last row is exposed that many frames after its first.

    Returns the image paths in frame order.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    say = progress or (lambda msg: None)
    say(f"ray casting {sim.rig.camera.width}x{sim.rig.camera.height} camera pixels")
    truth = sim.ground_truth()
    say(f"rendering {spec.n_frames} {spec.method} frame(s)")
    if motion is None:
        images, moved = sim.capture_sequence(list(spec.frames())), {}
    else:
        from rangekit.sim.devices.motion import capture_moving

        images, offsets = capture_moving(sim, list(spec.frames()), motion, readout_frames=readout_frames)
        moved = {"motion": asdict(motion), "frame_offsets_m": [float(o) for o in offsets],
                 "readout_frames": float(readout_frames)}
    paths = []
    for i, img in enumerate(images):
        path = out / f"{i:03d}.png"
        write_png(path, img)
        paths.append(path)
    atomic_write_json(out / PATTERNS_FILE, spec.to_dict())
    save_rig(sim.rig, out / RIG_FILE)
    angle = 0.0 if sim.turntable is None else sim.turntable.angle
    atomic_write_json(out / "capture.json", {
        "kind": "rangekit.sim.capture/1", "turntable_angle_rad": angle, "seed": sim.seed,
        "objects": list(sim.scene.names), "imaging": asdict(sim.imaging), "n_frames": spec.n_frames,
        **moved, **(info or {})})
    atomic_save_npz(out / "ground_truth.npz", depth=truth.depth, xyz=truth.xyz, normals=truth.normal,
                    proj_col=truth.proj_col, proj_row=truth.proj_row, valid=truth.lit, hit=truth.hit,
                    T_world_cam=sim.rig.camera.T_world_cam)
    white_index = spec.frame_names.index("white") if "white" in spec.frame_names else 0
    write_png(out / "preview.png", preview_image(images[white_index], truth))
    say(f"wrote {len(paths)} image(s), ground_truth.npz, {RIG_FILE} and preview.png to {out}")
    return paths
