"""Frames against accuracy (issue 51 Deliver 2): every pattern set :mod:`rangekit.app.scan.presets` names, and more
candidates, on the simulator's default object and the zoo's hard ones, against the simulator's exact truth.

    PYTHONPATH=. python benchmarks/coded/frames_vs_accuracy.py [--objects lumpy bowl thin] [--seed 1]
        [--sets NAME ...] [--json OUT.json] [--markdown]

One view (turntable at 0) of each object's default scene on the default simulated rig (1280x1024 camera, 1280x800
projector, 8 bit, noise, projector gamma 2.2, blur), captured with each pattern set's frames (both axes, as
``rangekit scan`` projects them) and reconstructed as ``rangekit process`` does a view
(:func:`rangekit.coded.reconstruct.reconstruct_view` with the rig's projector response: confidence 3%, the flying
pixel filter, one more pixel around depth edges). Per set and object:

- frames: captures per view;
- RMS and p95 (mm): the distance of each point from the exact surface point of its pixel (the simulator's
  ground-truth ``xyz``), root mean square and 95th percentile;
- completeness: the share of the object's lit visible pixels (truth: the object hit and the projector sees the
  point) that have a point.

A single view, not a fused scan: the fused mesh averages about 4 views a point (docs/benchmarks.md), so its RMS is
lower; the scan's figures for the sets a scan defaults to are in docs/coded-light.md ("Frames against accuracy").
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np

from rangekit.app.scan.presets import PRESETS, Preset
from rangekit.coded.reconstruct import reconstruct_view
from rangekit.sim import SimRig, default_scene


def candidates() -> dict[str, Preset]:
    """Set name -> pattern set: the presets, then other sets measured for comparison."""
    return {**PRESETS,
            "graycode": Preset("graycode", "Gray code, subpixel edges: 44 frames"),
            "micro": Preset("micro", "SLStudio's micro phase shifting: 24 frames")}


def measure(sim: SimRig, preset: Preset) -> dict:
    """One set on one object: frames, RMS and p95 (mm) of the points against the truth, completeness."""
    rig = sim.rig
    spec = preset.spec(rig.projector.size)
    t = time.time()
    stack = np.stack(sim.capture_sequence(list(spec.frames())))
    render_s = time.time() - t
    truth = sim.ground_truth()
    c = time.process_time()
    rec = reconstruct_view(stack, spec, rig.camera, rig.projector, response=rig.projector_response)
    cpu = time.process_time() - c
    visible = truth.hit & (truth.object_id == 0) & np.isfinite(truth.proj_col)
    point = rec.triangulated.valid & visible
    err = np.linalg.norm(rec.triangulated.xyz[point] - truth.xyz[point], axis=1) * 1e3
    return {"frames": spec.n_frames, "rms_mm": float(np.sqrt(np.mean(err ** 2))) if err.size else float("nan"),
            "p95_mm": float(np.percentile(err, 95)) if err.size else float("nan"),
            "completeness": float(point.sum() / max(visible.sum(), 1)), "reconstruct_cpu_s": cpu,
            "render_s": render_s}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--objects", nargs="+", default=["lumpy", "bowl", "thin"])
    ap.add_argument("--sets", nargs="+", default=None, help="set names (default: all of candidates())")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--json", default=None, help="write the rows to this file")
    ap.add_argument("--markdown", action="store_true", help="print docs/coded-light.md's table")
    args = ap.parse_args()
    sets = candidates()
    names = args.sets or list(sets)
    rows: dict[str, dict[str, dict]] = {}
    for obj in args.objects:
        sim = SimRig(default_scene(obj), seed=args.seed)
        for name in names:
            r = measure(sim, sets[name])
            rows.setdefault(name, {})[obj] = r
            print(f"{obj:6s} {name:24s} {r['frames']:3d} frames  RMS {r['rms_mm']:.4f} mm  p95 {r['p95_mm']:.4f} mm  "
                  f"complete {r['completeness']:.2%}  ({r['reconstruct_cpu_s']:.1f} CPU-s)", file=sys.stderr,
                  flush=True)
            if args.json:
                with open(args.json, "w") as f:
                    json.dump(rows, f, indent=1)
    if args.markdown:
        print("| set | frames | " + " | ".join(f"{o}: RMS / p95 (mm), complete" for o in args.objects) + " |")
        print("|---|---|" + "---|" * len(args.objects))
        for name in sorted(rows, key=lambda n: next(iter(rows[n].values()))["frames"]):
            cells = [f"{r['rms_mm']:.4f} / {r['p95_mm']:.4f}, {r['completeness']:.1%}"
                     for r in (rows[name][o] for o in args.objects)]
            print(f"| `{name}` | {next(iter(rows[name].values()))['frames']} | " + " | ".join(cells) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
