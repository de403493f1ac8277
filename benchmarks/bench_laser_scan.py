"""The whole laser-line scan on the simulator: 400 turntable steps, two lasers (acceptance, issue 17).

Target: acquire + process (laser-plane calibration from 10 simulated board poses, 1,200 frames rendered and
written, peaks, triangulation, fusion, accuracy against the truth, report) in at most 3 minutes on a
2-core machine. Runs the command a user runs, as a separate process, and reads its stage times from
``summary.json``:

    .venv/bin/python benchmarks/bench_laser_scan.py [--object NAME_OR_MESH] [--up X Y Z] [--steps 400]

Prints the wall time, the stage times and the accuracy, and exits non-zero if the target is missed.
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


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--object", default="lumpy")
    ap.add_argument("--up", nargs=3)
    ap.add_argument("--steps", type=int, default=400)
    args = ap.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "scan"
        cmd = [sys.executable, "-m", "rangekit", "scan", "--method", "laser", "--steps", str(args.steps),
               "--object", args.object, "--out", str(out)] + (["--up", *args.up] if args.up else [])
        t = time.perf_counter()
        run = subprocess.run(cmd, capture_output=True, text=True)
        wall = time.perf_counter() - t
        if run.returncode != 0:
            print(run.stderr)
            return run.returncode
        summary = json.loads((out / "summary.json").read_text())
    acquisition = next((ln for ln in run.stdout.splitlines() if ln.startswith("acquisition:")), "")
    a = summary["accuracy"]
    print(f"{args.steps}-step two-laser scan of {args.object}: {wall:.1f} s wall (acquire + process), target "
          f"{TARGET_S:.0f} s; {acquisition}; processing stages: "
          + ", ".join(f"{k} {v:.1f} s" for k, v in summary["seconds"].items()))
    print(f"cloud RMS {a['cloud_rms'] * 1e3:.4f} mm over {a['n_cloud']:,} points; mesh RMS {a['rms'] * 1e3:.4f} mm, "
          f"completeness {a['completeness']:.1%}")
    return 0 if wall <= TARGET_S else 1


if __name__ == "__main__":
    sys.exit(main())
