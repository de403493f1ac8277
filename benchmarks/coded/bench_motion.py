"""Motion detection in a Gray-code capture (issue 38 item 3, rangekit.coded.motion) against the simulator's truth.

    PYTHONPATH=. .venv/bin/python benchmarks/coded/bench_motion.py [OBJECT] [--mm 0.5] [--at FRAME] [--dir X,Y,Z]

The default rig and OBJECT (default the default scene's), a slip of ``--mm`` millimetres along ``--dir`` (world, default
x) before frame ``--at`` (default halfway through the sequence). Captured three times: moving, still (the object
where it was; the same noise stream as the moving capture's frames before the slip) and still where it went. A
pixel is *spoiled* when the moving capture's column is valid and further from the true column than the still
capture's by more than half a code, against both truths (where the object was, and where it went): the slip made
it worse than either surface decodes. Printed (JSON): the share of decoded pixels spoiled, the share of them the
``motion`` mask flags, the mask's share on the moving capture and on the still one (false flags), the frames
named, and the decode's time with and without the check (CPU seconds of the calling process, best of 3).
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from rangekit.coded.decode import decode
from rangekit.coded.patterns import make_pattern_spec
from rangekit.sim import SimRig, default_rig, default_scene
from rangekit.sim.devices.motion import Motion, capture_moving
from rangekit.sim.scene.passes import pass_scene


def worse(m: np.ndarray, s: np.ndarray, truth: np.ndarray, margin: float = 0.5) -> np.ndarray:
    """``m`` valid and further from ``truth`` than ``s`` (NaN: as close as the truth) by more than ``margin``."""
    em = np.abs(m - truth)
    es = np.nan_to_num(np.abs(s - truth), nan=0.0)
    return np.isfinite(m) & np.isfinite(truth) & (em > es + margin)


def _cpu(f) -> float:
    best = np.inf
    for _ in range(3):
        c0 = time.process_time()
        f()
        best = min(best, time.process_time() - c0)
    return best


def main() -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("object", nargs="?", default=None)
    ap.add_argument("--mm", type=float, default=0.5)
    ap.add_argument("--at", type=int, default=None)
    ap.add_argument("--dir", default="1,0,0")
    args = ap.parse_args()
    rig = default_rig()
    spec = make_pattern_spec("graycode", (rig.projector.width, rig.projector.height))
    frames = list(spec.frames())
    at = len(frames) // 2 if args.at is None else args.at
    motion = Motion("slip", args.mm * 1e-3, direction=tuple(float(v) for v in args.dir.split(",")), at_frame=at)
    scene = default_scene() if args.object is None else default_scene(args.object)
    moved_scene = pass_scene(scene, motion.motion(len(frames)))
    still = SimRig(scene, rig, seed=5).capture_sequence(frames)
    moved = SimRig(moved_scene, rig, seed=5).capture_sequence(frames)
    moving, _ = capture_moving(SimRig(scene, rig, seed=5), frames, motion)
    truth_still, truth_moved = SimRig(scene, rig).ground_truth(), SimRig(moved_scene, rig).ground_truth()
    ds, dv, dm = (decode(x, spec, motion=False) for x in (still, moved, moving))
    spoiled = (worse(dm.proj_col, ds.proj_col, truth_still.proj_col)
               & worse(dm.proj_col, dv.proj_col, truth_moved.proj_col))
    checked, calm = decode(moving, spec, motion=True, max_motion=None), decode(still, spec, motion=True, max_motion=None)
    decoded_m, decoded_s = np.isfinite(dm.proj_col), np.isfinite(ds.proj_col)
    return {"object": args.object or "default", "slip_mm": args.mm, "before_frame": spec.frame_names[at],
            "spoiled_share": round(float(spoiled.sum() / decoded_m.sum()), 4),
            "spoiled_flagged": round(float((checked.motion & spoiled).sum() / max(spoiled.sum(), 1)), 4),
            "flagged_moving": round(float((checked.motion & decoded_m).sum() / decoded_m.sum()), 4),
            "false_flags_still": round(float((calm.motion & decoded_s).sum() / decoded_s.sum()), 5),
            "frames_named": list(checked.moved_frames),
            "decode_cpu_s": {"checked": round(_cpu(lambda: decode(still, spec, motion=True, max_motion=None)), 3),
                             "unchecked": round(_cpu(lambda: decode(still, spec, motion=False)), 3)}}


if __name__ == "__main__":
    print(json.dumps(main()))
