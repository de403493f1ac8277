"""The whole laser-line scan on the simulator: 400 turntable steps, two lasers (laser-line scanning's acceptance test).

Target: acquire + process (laser-plane calibration from 10 simulated board poses, 1,200 frames rendered and
written, peaks, triangulation, fusion, accuracy against the truth, report) in at most 3 minutes on a
2-core machine. Runs the command a user runs, as a separate process, and reads its stage times from
``summary.json``:

    .venv/bin/python benchmarks/laser/bench_laser_scan.py [--object NAME_OR_MESH] [--up X Y Z] [--steps 400]

Prints the wall time, the stage times and the accuracy, and exits non-zero if the target is missed.
``--markdown`` scans lumpy and the zoo's upright Stanford bunny (``--object bunny``; skipped without the
shared data) and prints docs/benchmarks.md's table (a ``make docs-figures`` block; exit 0 even if missed).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGET_S = 180.0


def scan(obj: str, up, steps: int):
    """(wall seconds, the 'acquisition:' line of stdout, summary.json) of one laser scan, or raise."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "scan"
        cmd = [sys.executable, "-m", "rangekit", "scan", "--method", "laser", "--steps", str(steps),
               "--object", obj, "--out", str(out)] + (["--up", *up] if up else [])
        t = time.perf_counter()
        run = subprocess.run(cmd, capture_output=True, text=True)
        wall = time.perf_counter() - t
        if run.returncode != 0:
            raise SystemExit(f"{' '.join(cmd)} failed (exit {run.returncode}):\n{run.stderr}")
        summary = json.loads((out / "summary.json").read_text())
    acquisition = next((ln for ln in run.stdout.splitlines() if ln.startswith("acquisition:")), "")
    return wall, acquisition, summary


def markdown(steps: int) -> int:
    """docs/benchmarks.md's table: lumpy and the upright bunny, one row each."""
    from rangekit.sim.scene.zoo import bunny_path

    objects = [("lumpy", "lumpy")] + ([("Stanford bunny upright (`--object bunny`)", "bunny")]
                                      if bunny_path().is_file() else [])
    print("| object | wall time | acquisition | profiles | fuse | evaluate | report | cloud RMS | mesh RMS | "
          "completeness |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    missed = []
    for label, obj in objects:
        wall, acquisition, summary = scan(obj, None, steps)
        sec, a = summary["seconds"], summary["accuracy"]
        acq = acquisition.split(":", 1)[1].split(",")[0].strip() if acquisition else "-"
        stages = " | ".join(f"{sec[k]:.1f} s" if k in sec else "-" for k in ("profiles", "fuse", "evaluate", "report"))
        print(f"| {label} | **{int(wall // 60)} min {wall % 60:.0f} s** | {acq} | {stages} | "
              f"{a['cloud_rms'] * 1e3:.3f} mm | {a['rms'] * 1e3:.3f} mm | {a['completeness']:.1%} |")
        if wall > TARGET_S:
            missed.append(obj)
    print(f"\nTarget (at most {TARGET_S / 60:.0f} minutes): " + (f"missed for {', '.join(missed)}." if missed
                                                                   else "met for both." if len(objects) > 1 else "met."))
    return 0


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--object", default="lumpy")
    ap.add_argument("--up", nargs=3)
    ap.add_argument("--steps", type=int, default=400)
    ap.add_argument("--markdown", action="store_true", help="lumpy and bunny: the table of docs/benchmarks.md")
    args = ap.parse_args()
    if args.markdown:
        return markdown(args.steps)
    wall, acquisition, summary = scan(args.object, args.up, args.steps)
    a = summary["accuracy"]
    print(f"{args.steps}-step two-laser scan of {args.object}: {wall:.1f} s wall (acquire + process), target "
          f"{TARGET_S:.0f} s; {acquisition}; processing stages: "
          + ", ".join(f"{k} {v:.1f} s" for k, v in summary["seconds"].items()))
    print(f"cloud RMS {a['cloud_rms'] * 1e3:.4f} mm over {a['n_cloud']:,} points; mesh RMS {a['rms'] * 1e3:.4f} mm, "
          f"completeness {a['completeness']:.1%}")
    return 0 if wall <= TARGET_S else 1


if __name__ == "__main__":
    sys.exit(main())
