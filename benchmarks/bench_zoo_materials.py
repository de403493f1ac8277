"""What the zoo's materials do to the default camera: saturated pixels and the median grey level under the
white pattern, on the object's lit pixels, for ``lumpy``, ``shiny`` and ``dark`` (the same shape).

    .venv/bin/python benchmarks/bench_zoo_materials.py [--angles 0 1 2 3 4 5] [--seed 0]

Prints one line per object: per turntable angle (radians), saturated / lit object pixels and the median
digital number (8 bits). The figures are quoted in docs/simulator.md (the zoo).
"""

from __future__ import annotations

import argparse

import numpy as np

from rangekit.sim import SimRig, default_scene


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--angles", type=float, nargs="+", default=[0, 1, 2, 3, 4, 5], help="turntable angles, rad")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()
    for name in ("lumpy", "shiny", "dark"):
        sim = SimRig(default_scene(name), seed=args.seed)
        w, h = sim.projector.resolution
        cells = []
        for angle in args.angles:
            sim.turntable.rotate_to(angle)
            img = sim.capture_sequence([np.full((h, w), 255, np.uint8)])[0]
            truth = sim.ground_truth()
            obj = truth.lit & (truth.object_id == 0)
            full = int(np.count_nonzero(img[obj] >= sim.imaging.max_value))
            cells.append(f"{angle:g}: {full}/{int(obj.sum())} sat, median {np.median(img[obj]):.0f}")
        print(f"{name:6s} " + "; ".join(cells), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
