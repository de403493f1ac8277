"""The report and the evaluation of ``rangekit process``, in CPU seconds (the speed targets of rangekit process).

    PYTHONPATH=. python benchmarks/app/bench_report.py capture SESSION_COPY   # once: process, keep the inputs
    PYTHONPATH=. python benchmarks/app/bench_report.py time [--part report|evaluate] [--code OTHER_TREE] [--warm]
        [--repeat R]
    PYTHONPATH=. python benchmarks/app/bench_report.py markdown SESSION   # docs/benchmarks.md's block

``markdown`` copies SESSION (left unchanged) into ``$RANGEKIT_DOCS_WORK/report12``, captures there (the
pickles too: ``BENCH_REPORT_STORE``, default the temporary folder, names where they go), then times
``time --warm --repeat 2`` and ``time --part evaluate --repeat 2`` in two child processes and prints the
table (a ``make docs-figures`` block).

``capture`` processes SESSION_COPY (a copy of a ``rangekit scan --no-process`` session: processing writes its
caches and outputs there) with this tree, pickling what :func:`rangekit.app.report.page.write_report` and the
simulator's evaluator (:class:`rangekit.sim.truth.evaluate.TruthEvaluator`) receive into the temporary folder
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

import os
import pickle
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]  # the repo (this is benchmarks/ROOM/SCRIPT.py)
CODE = Path(sys.argv[sys.argv.index("--code") + 1]) if "--code" in sys.argv[:-1] else ROOT
sys.path.insert(0, str(CODE))
STORE = Path(os.environ.get("BENCH_REPORT_STORE") or tempfile.gettempdir())
REPORT_TARGET_S = 3.0
REPORT, EVAL = STORE / "bench_report_inputs.pkl", STORE / "bench_report_eval.pkl"


def capture(session: str) -> None:
    import rangekit.app.report.page as report
    import rangekit.sim.truth.evaluate as evaluate
    from rangekit.app.scan.scan import process
    from rangekit._runtime.threads import one_blas_thread

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
        process(session)
    print(f"kept {REPORT} and {EVAL}")


def _cpu(fn) -> float:
    c0 = time.process_time()
    fn()
    return time.process_time() - c0


def run_once(part: str, warm: bool) -> dict:
    import numpy as np
    import open3d as o3d

    from rangekit.app.report.page import write_report
    from rangekit.sim.truth.evaluate import TruthEvaluator
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


def markdown(session: str) -> str:
    """Capture on a copy of SESSION in $RANGEKIT_DOCS_WORK, time the report and the evaluation (min of 2,
    each in a child process), and return docs/benchmarks.md's table."""
    work = Path(os.environ.get("RANGEKIT_DOCS_WORK") or ROOT / "build" / "docs-figures")
    copy, store = work / "report12", work / "report_inputs"
    shutil.rmtree(copy, ignore_errors=True)
    shutil.copytree(session, copy)
    store.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, BENCH_REPORT_STORE=str(store))
    me = [sys.executable, str(Path(__file__).resolve())]
    try:
        subprocess.run([*me, "capture", str(copy)], env=env, check=True, stdout=sys.stderr, stdin=subprocess.DEVNULL)
        cpu = {}
        for extra in (["--warm"], ["--part", "evaluate"]):
            done = subprocess.run([*me, "time", *extra, "--repeat", "2"], env=env, check=True, text=True,
                                  stdout=subprocess.PIPE, stdin=subprocess.DEVNULL)
            cpu.update({m[1].strip(): float(m[2]) for m in re.finditer(r"^(.+?)\s+([\d.]+) CPU s", done.stdout, re.M)})
    finally:
        shutil.rmtree(store, ignore_errors=True)   # about 800 MB of pickles
        shutil.rmtree(copy, ignore_errors=True)
    report = cpu["report"]
    return "\n".join([
        "| part | CPU s (min of 2) |", "|---|---|",
        f"| `write_report` (the meshes' ray-casting scenes already built, as in `rangekit process`) | {report:.2f} |",
        f"| evaluator `prepare` (truth samples + per-view errors) | {cpu['evaluate: prepare']:.2f} |",
        f"| accuracy of the two meshes | {cpu['evaluate: two meshes']:.2f} |", "",
        f"Report target {REPORT_TARGET_S:g} CPU-s: {'met' if report <= REPORT_TARGET_S else 'not met'} in this run.",
    ])


def main() -> None:
    if len(sys.argv) >= 3 and sys.argv[1] == "capture":
        return capture(sys.argv[2])
    if len(sys.argv) >= 3 and sys.argv[1] == "markdown":
        print(markdown(sys.argv[2]))
        return
    from rangekit._runtime.threads import one_blas_thread

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
