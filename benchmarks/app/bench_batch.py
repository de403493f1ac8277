"""Four sessions one after another against the same four on a Dask ``LocalCluster`` of 2 workers (docs/scale.md).

    PYTHONPATH=. python benchmarks/app/bench_batch.py [--sessions 4] [--workers 2]

The session is the shared default 12-view one of ``tools/docs_scan.py session`` (``rangekit scan
--no-process``, made on first use under ``$RANGEKIT_DOCS_WORK``). It is copied ``2 x --sessions`` times to
``$RANGEKIT_DOCS_WORK/batch/s1 ...`` (processing writes its view cache into the session, so each run gets
fresh copies) and the copies are flushed to disk before any timing (the kernel writing them back would
otherwise run during the first measurement). Then, each under ``benchmarks/harness/tree_peak.py`` (wall, CPU of the
process tree, peak of the tree):

- serial: ``python -m rangekit -q process Sk`` for the first half, one after another (default settings);
- batch: ``python -m rangekit -q process S5 S6 S7 S8 --workers 2`` on the second half.

Printed: both rows, the throughput ratio (serial wall / batch wall; the target is >= 1.5) and whether
``mesh.ply``, ``mesh_watertight.ply``, ``poses.json`` and ``merged.ply`` of every batch session are the bytes
of the first serial one, as docs/scale.md's table (a ``make docs-figures`` block); each run's line goes to
stderr as it ends. The copies are removed at the end. About 5 minutes on an idle 2-core machine.
"""

from __future__ import annotations

import argparse
import os
import shutil
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]  # the repo (this is benchmarks/ROOM/SCRIPT.py)
sys.path[:0] = [str(ROOT / "benchmarks" / "harness"), str(ROOT / "tools")]  # _timing, tree_peak; docs_scan
import docs_scan  # noqa: E402  (the shared session of make docs-figures)
import tree_peak  # noqa: E402

OUTPUTS = ("mesh.ply", "mesh_watertight.ply", "poses.json", "merged.ply")
TARGET = 1.5


def _rangekit(*args: str) -> list[str]:
    return [sys.executable, "-m", "rangekit", "-q", "process", *args]


def _checked(run: dict, what: str) -> dict:
    if run["exit"]:
        raise SystemExit(f"{what} failed (exit {run['exit']}):\n{run['stderr'][-3000:]}")
    print(f"{what}: {run['wall_s']:.1f} s wall, {run['cpu_s']:.1f} CPU-s, peak {run['peak_gb']:.2f} GB",
          file=sys.stderr, flush=True)
    return run


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sessions", type=int, default=4)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    session = docs_scan.ensure_session()
    root = docs_scan.WORK / "batch"
    shutil.rmtree(root, ignore_errors=True)
    copies = [shutil.copytree(session, root / f"s{k + 1}") for k in range(2 * args.sessions)]
    os.sync()
    serial_copies, batch_copies = copies[: args.sessions], copies[args.sessions:]
    try:
        serial = [_checked(tree_peak.measured(_rangekit(str(c)), cwd=docs_scan.REPO), f"rangekit process {c}")
                  for c in serial_copies]
        batch = _checked(tree_peak.measured(_rangekit(*map(str, batch_copies), "--workers", str(args.workers)),
                                            cwd=docs_scan.REPO), "rangekit process (batch)")
        same = all((c / name).read_bytes() == (serial_copies[0] / name).read_bytes()
                   for c in batch_copies for name in OUTPUTS)
    finally:
        shutil.rmtree(root, ignore_errors=True)
    wall = sum(r["wall_s"] for r in serial)
    ratio = wall / batch["wall_s"]
    each = f"{min(r['wall_s'] for r in serial):.1f}-{max(r['wall_s'] for r in serial):.1f} s each"
    n = args.sessions
    rows = [
        "| run | wall | CPU (user + sys) | peak of the tree |",
        "|---|---|---|---|",
        f"| `rangekit process` of {n} sessions one after another | {wall:.1f} s ({each}) | "
        f"{sum(r['cpu_s'] for r in serial):.1f} CPU-s | {max(r['peak_gb'] for r in serial):.2f} GB |",
        f"| `rangekit process` of the {n} others `--workers {args.workers}` | {batch['wall_s']:.1f} s | "
        f"{batch['cpu_s']:.1f} CPU-s | {batch['peak_gb']:.2f} GB |",
    ]
    verdict = (f"Throughput {wall:.1f} / {batch['wall_s']:.1f} = **{ratio:.2f}x** (target {TARGET}x: "
               f"{'met' if ratio >= TARGET else 'not met'} in this run). `mesh.ply`, `mesh_watertight.ply`, "
               f"`poses.json` and `merged.ply` of the batch are {'' if same else 'NOT '}byte-identical to serial "
               "processing's.")
    print("\n".join(rows) + "\n\n" + verdict)
    if not same:
        sys.exit(1)


if __name__ == "__main__":
    main()
