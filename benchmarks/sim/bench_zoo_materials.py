"""What the zoo's materials do to the default camera: saturated pixels and the median grey level under the
white pattern, on the object's lit pixels, for ``lumpy``, ``shiny`` and ``dark`` (the same shape).

    .venv/bin/python benchmarks/sim/bench_zoo_materials.py [--angles 0 1 2 3 4 5] [--seed 0]

Prints one line per object: per turntable angle (radians), saturated / lit object pixels and the median
digital number (8 bits). The figures are quoted in docs/simulator.md (the zoo): ``--markdown`` prints its
sentence, the ranges over the angles (a ``make docs-figures`` block).
"""

from __future__ import annotations

import argparse

import numpy as np

from rangekit.sim import SimRig, default_scene


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--angles", type=float, nargs="+", default=[0, 1, 2, 3, 4, 5], help="turntable angles, rad")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--markdown", action="store_true", help="print docs/simulator.md's sentence")
    args = ap.parse_args()
    parts = []
    for name in ("lumpy", "shiny", "dark"):
        sim = SimRig(default_scene(name), seed=args.seed)
        w, h = sim.projector.resolution
        cells, sat, lit, med = [], [], [], []
        for angle in args.angles:
            sim.turntable.rotate_to(angle)
            img = sim.capture_sequence([np.full((h, w), 255, np.uint8)])[0]
            truth = sim.ground_truth()
            obj = truth.lit & (truth.object_id == 0)
            full = int(np.count_nonzero(img[obj] >= sim.imaging.max_value))
            sat.append(full), lit.append(int(obj.sum())), med.append(float(np.median(img[obj])))
            cells.append(f"{angle:g}: {full}/{int(obj.sum())} sat, median {np.median(img[obj]):.0f}")
        if not args.markdown:
            print(f"{name:6s} " + "; ".join(cells), flush=True)
            continue
        share = [a / b for a, b in zip(sat, lit)]
        dn = f"median {min(med):.0f}-{max(med):.0f} DN"
        parts.append(f"`{name}` has {min(sat):,}-{max(sat):,} of {min(lit) / 1e3:.0f}k-{max(lit) / 1e3:.0f}k pixels at "
                     f"255 ({min(share):.1%}-{max(share):.1%}), {dn}" if max(sat) else f"`{name}` none saturated, {dn}")
    if args.markdown:
        angles = ", ".join(f"{a:g}" for a in args.angles)
        print(f"The white pattern at turntable angles {angles} rad on the default rig, seed {args.seed}, the "
              f"object's pixels lit by the projector: {'; '.join(parts)}.")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
