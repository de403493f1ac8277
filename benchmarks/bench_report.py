"""The report and the evaluation of ``rangekit process``, in CPU seconds (issue 20).

    PYTHONPATH=. python benchmarks/bench_report.py capture SESSION_COPY   # once: process, keep the inputs
    PYTHONPATH=. python benchmarks/bench_report.py time [--part report|evaluate] [--code OTHER_TREE] [--warm]
        [--repeat R]

``capture`` processes SESSION_COPY (a copy of a ``rangekit scan --no-process`` session: processing writes its
caches and outputs there) with this tree, pickling what :func:`rangekit.app.report.write_report` and the
simulator's evaluator (:class:`rangekit.sim.evaluate.TruthEvaluator`) receive into the temporary folder
(``bench_report_*.pkl``, about 800 MB). ``time`` then runs on those inputs either (``--part report``, the
default) ``write_report`` into a temporary folder, or (``--part evaluate``; a separate process: Open3D's
worker threads left busy by one part inflate the other's CPU) the evaluator's mesh-independent half
(``prepare``: truth samples, their visibility, the per-view errors) and the accuracy of the observed and
the closed mesh, each timed with
``time.process_time()`` (user + sys, every thread), minimum of ``--repeat`` runs. ``--warm`` builds and
commits the meshes' ray-casting scenes before the report, as processing does now (the accuracy builds them
and the report reuses them); a tree before that change builds them in the report, so time it without.
``--code TREE`` imports another checkout's rangekit (before/after in the same session, alternating).
"""

from __future__ import annotations

import pickle
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CODE = Path(sys.argv[sys.argv.index("--code") + 1]) if "--code" in sys.argv[:-1] else ROOT
sys.path.insert(0, str(CODE))
STORE = Path(tempfile.gettempdir())
REPORT, EVAL = STORE / "bench_report_inputs.pkl", STORE / "bench_report_eval.pkl"


def capture(session: str) -> None:
    import rangekit.app.report as report
    import rangekit.sim.evaluate as evaluate
    from rangekit.app.scan import process_scan
    from rangekit.threads import one_blas_thread

    write, prepare = report.write_report, evaluate.TruthEvaluator.prepare

    def keep_report(folder, result, **kw):
        with open(REPORT, "wb") as f:
            pickle.dump((result, {k: v for k, v in kw.items() if k != "progress"}), f, protocol=5)
        return write(folder, result, **kw)

    def keep_eval(self, angles, views=None):
        if views is not None:
            with open(EVAL, "wb") as f:
                pickle.dump((self.scene, self.rig, self.options, list(angles), views), f, protocol=5)
        return prepare(self, angles, views)

    report.write_report, evaluate.TruthEvaluator.prepare = keep_report, keep_eval
    with one_blas_thread():
        process_scan(session)
    print(f"kept {REPORT} and {EVAL}")


def _cpu(fn) -> float:
    c0 = time.process_time()
    fn()
    return time.process_time() - c0


def run_once(part: str, warm: bool) -> dict:
    import numpy as np
    import open3d as o3d

    from rangekit.app.report import write_report
    from rangekit.sim.evaluate import TruthEvaluator
    from rangekit.surface.raycast import mesh_scene

    result, kw = pickle.load(open(REPORT, "rb"))
    scene, rig, options, angles, views = pickle.load(open(EVAL, "rb"))
    out = {}
    if part == "evaluate":
        ev = TruthEvaluator(scene, rig, options)
        out["evaluate: prepare"] = _cpu(lambda: ev.prepare(angles, views))
        out["evaluate: two meshes"] = _cpu(lambda: (ev(kw["mesh"], angles), ev(kw["watertight"], angles)))
        return out
    if warm:   # the meshes' scenes as the accuracy leaves them (the pickled meshes are new objects)
        for m in (kw["mesh"], kw["watertight"], kw["truth"]):
            s, _ = mesh_scene(m)
            s.compute_closest_points(o3d.core.Tensor(np.zeros((1, 3), np.float32)))
    with tempfile.TemporaryDirectory() as tmp:
        out["report"] = _cpu(lambda: write_report(tmp, result, **kw))
    return out


def main() -> None:
    if len(sys.argv) >= 3 and sys.argv[1] == "capture":
        return capture(sys.argv[2])
    from rangekit.threads import one_blas_thread

    part = sys.argv[sys.argv.index("--part") + 1] if "--part" in sys.argv[:-1] else "report"
    repeat = int(sys.argv[sys.argv.index("--repeat") + 1]) if "--repeat" in sys.argv[:-1] else 3
    best: dict = {}
    with one_blas_thread():
        for _ in range(repeat):
            for k, v in run_once(part, "--warm" in sys.argv).items():
                best[k] = min(best.get(k, v), v)
    print(f"code: {CODE}")
    for k, v in best.items():
        print(f"{k:22s} {v:6.2f} CPU s (min of {repeat})")


if __name__ == "__main__":
    main()
