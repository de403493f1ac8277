"""``rangekit process`` of the default 12-view session vs its speed targets: wall, CPU, tree peak, stages, accuracy.

    PYTHONPATH=. python benchmarks/app/bench_process.py [--markdown]   # time one run on a fresh copy
    PYTHONPATH=. python benchmarks/app/bench_process.py --processed    # print the processed copy's path

The session is the shared default one of ``tools/docs_scan.py session`` (``rangekit scan --no-process``,
made on first use under ``$RANGEKIT_DOCS_WORK``). It is copied to ``$RANGEKIT_DOCS_WORK/process12`` (no view
cache) and processed by ``python -m rangekit process COPY`` under ``benchmarks/harness/tree_peak.py``: wall seconds,
CPU seconds (user + sys) of the command and its children, and the peak of the whole process tree (Poisson
runs in a child process). The stage seconds (wall) and the meshes' accuracy against the simulator's truth
are read from the copy's ``summary.json``. The accuracy is deterministic (seeded scan, reproducible
mesh); the times are not.

``--markdown`` prints the row and the accuracy sentence of docs/benchmarks.md (a ``make docs-figures``
block); without it a plain report. ``--processed`` prints the path of the processed copy, processing it
first when no run left one (the input of ``bench_registration_scan.py``'s figure).
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]  # the repo (this is benchmarks/ROOM/SCRIPT.py)
sys.path[:0] = [str(ROOT / "benchmarks" / "harness"), str(ROOT / "tools")]  # _timing, tree_peak; docs_scan
import docs_scan  # noqa: E402  (the shared session of make docs-figures)
import tree_peak  # noqa: E402

COPY = docs_scan.WORK / "process12"
TARGETS = {"wall_s": 30.0, "cpu_s": 40.0, "peak_gb": 1.5}


def process_copy() -> dict:
    """Process a fresh copy of the shared session under tree_peak; {wall_s, cpu_s, peak_gb}."""
    session = docs_scan.ensure_session()
    shutil.rmtree(COPY, ignore_errors=True)
    shutil.copytree(session, COPY)
    run = tree_peak.measured([sys.executable, "-m", "rangekit", "-q", "process", str(COPY)], cwd=docs_scan.REPO)
    if run["exit"]:
        shutil.rmtree(COPY, ignore_errors=True)
        raise SystemExit(f"rangekit process {COPY} failed (exit {run['exit']}):\n{run['stderr'][-3000:]}")
    return {k: run[k] for k in ("wall_s", "cpu_s", "peak_gb")}


def processed() -> Path:
    """The processed copy, made (untimed) when no run left one."""
    if not (COPY / "summary.json").exists():
        process_copy()
    return COPY


def markdown(run: dict, summary: dict) -> str:
    sec, acc = summary["seconds"], summary["accuracy"]
    closed = acc["watertight"]
    head = "| | wall | CPU-s (user + sys) | tree peak | " + " | ".join(sec) + " |"
    rule = "|---" * (4 + len(sec)) + "|"
    now = (f"| now (`make docs-figures`) | {run['wall_s']:.1f} s | {run['cpu_s']:.1f} | {run['peak_gb']:.2f} GB | "
           + " | ".join(f"{v:.1f}" for v in sec.values()) + " |")
    target = (f"| target | <= {TARGETS['wall_s']:.0f} s | <= {TARGETS['cpu_s']:.0f} | <= {TARGETS['peak_gb']} GB |"
              + " |" * len(sec))
    met = [name for name, key in (("wall", "wall_s"), ("CPU", "cpu_s"), ("peak", "peak_gb"))
           if run[key] <= TARGETS[key]]
    return "\n".join([
        head, rule, now, target, "",
        f"Targets met in this run: {', '.join(met) if met else 'none'}. Accuracy against the simulator's truth: "
        f"observed mesh {acc['rms'] * 1e3:.4f} mm RMS, 95th percentile {acc['p95'] * 1e3:.4f} mm, completeness "
        f"{acc['completeness'] * 100:.1f}%; closed mesh {closed['rms'] * 1e3:.3f} mm RMS.",
    ])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--markdown", action="store_true", help="print the docs/benchmarks.md block")
    ap.add_argument("--processed", action="store_true", help="print the processed copy's path (process if needed)")
    args = ap.parse_args()
    if args.processed:
        print(processed())
        return 0
    run = process_copy()
    summary = json.loads((COPY / "summary.json").read_text())
    if args.markdown:
        print(markdown(run, summary))
        return 0
    print(f"rangekit process {COPY}: {run['wall_s']:.1f} s wall, {run['cpu_s']:.1f} CPU-s, tree peak "
          f"{run['peak_gb']:.2f} GB")
    print("stage wall s:", {k: round(v, 1) for k, v in summary["seconds"].items()})
    acc = summary["accuracy"]
    print(f"observed mesh RMS {acc['rms'] * 1e3:.4f} mm, p95 {acc['p95'] * 1e3:.4f} mm, completeness "
          f"{acc['completeness'] * 100:.1f}%; closed mesh RMS {acc['watertight']['rms'] * 1e3:.3f} mm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
