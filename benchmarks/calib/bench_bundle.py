"""The camera-projector bundle adjustment, MINPACK on finite differences (before issue 38) against Levenberg-Marquardt
on the reduced system with the analytic Jacobian (issue 38 item 5), side by side in one run, alternating.

    .venv/bin/python benchmarks/calib/bench_bundle.py [POSES [REPEATS]]     # default 40 poses, 5 repeats

The problem: the simulator's true camera and projector, POSES hand-held board poses (54 corners each, seen by
both devices with 0.03 px of noise), started from focal lengths 1% off, no distortion and poses 0.5 deg / 2 mm
off (tests/support/bundle_problems.py). Prints JSON: per solver the median seconds, the evaluations, the weighted cost.
"""

from __future__ import annotations

import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))

from support.bundle_problems import bundle_problem  # noqa: E402

from rangekit.calib.projector import bundle_adjust  # noqa: E402


def main(n_poses: int = 40, repeats: int = 5) -> dict:
    _, _, _, start = bundle_problem(n_poses)
    bundle_adjust(**start, solver="schur")          # imports and first-call costs out of the timing
    times: dict = {"minpack": [], "schur": []}
    result = {}
    for _ in range(repeats):
        for solver in ("minpack", "schur"):
            t0 = time.perf_counter()
            res = bundle_adjust(**start, solver=solver)
            times[solver].append(time.perf_counter() - t0)
            result[solver] = {"evaluations": res.nfev, "cost": res.rms_camera ** 2 / 0.05 ** 2
                              + res.rms_projector ** 2 / 0.1 ** 2}
    out = {s: {"median_s": round(statistics.median(t), 3), "runs_s": [round(x, 3) for x in t], **result[s]}
           for s, t in times.items()}
    out["speed_up"] = round(out["minpack"]["median_s"] / out["schur"]["median_s"], 2)
    out["poses"] = n_poses
    return out


if __name__ == "__main__":
    print(json.dumps(main(*(int(a) for a in sys.argv[1:3]))))
