"""``rangekit process`` of one session by two code trees side by side, alternating: wall, CPU, tree peak, accuracy.

    PYTHONPATH=. python benchmarks/app/bench_process_vs.py SESSION OLD_TREE [--new-tree .] [--pairs 5] \
        [--new-session SESSION2]

``SESSION``: a session as ``rangekit scan --out SESSION --no-process`` leaves it (issue 36 used the default one).
``OLD_TREE``: another checkout of rangekit, e.g. ``git worktree add ../wt-cc6 cc6da01`` with the links
``rangekit/{sim,drivers,calib} -> ../{sim,drivers,calib}`` (the editable install maps those packages; a
worktree needs them to import ``rangekit.sim``). Each tree processes its own copy of the session
(``SESSION.new``, ``SESSION.old``, made once); before each run the copy's view caches (``view_*/cloud.ply,
maps.npz, cloud.json``) and outputs are removed, so every run decodes every frame. Runs alternate new, old,
new, old ..., after one untimed warm-up each (numba's on-disk caches); each run is ``python -m rangekit -q process
COPY`` with ``PYTHONPATH`` at its tree, under ``benchmarks/harness/tree_peak.py`` (wall seconds, CPU seconds of
the command and its children, the peak of its process tree). Printed: the median, min and max of each figure
and of the new/old ratio taken pair by pair (a machine whose speed drifts moves both runs of a pair), and the
accuracy of each tree's last run against the simulator's truth (``summary.json``), which is deterministic.

``--new-session SESSION2``: the new tree processes a copy of SESSION2 instead, the same scan in a format the old
tree cannot read (``rangekit scan --out SESSION2 --no-process`` on the new tree writes ``.npy.zst`` frames, the
same pixels as the old tree's PNGs: tests/formats/test_npy_zst_frames.py).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]  # the repo (this is benchmarks/ROOM/SCRIPT.py)
sys.path[:0] = [str(ROOT / "benchmarks" / "harness"), str(ROOT / "tools")]  # _timing, tree_peak; docs_scan
import tree_peak  # noqa: E402

#: What processing writes into a session folder (removed before each run).
OUTPUTS = ("mesh.ply", "mesh_watertight.ply", "merged.ply", "poses.json", "summary.json", "report.html")
CACHE = ("cloud.ply", "maps.npz", "cloud.json")
FIGURES = ("wall_s", "cpu_s", "peak_gb")


def _fresh(copy: Path) -> None:
    """Remove the copy's view caches and outputs: the next run decodes every frame."""
    for name in OUTPUTS:
        (copy / name).unlink(missing_ok=True)
    for view in copy.glob("view_*"):
        for name in CACHE:
            (view / name).unlink(missing_ok=True)


def _run(tree: Path, copy: Path) -> dict:
    _fresh(copy)
    env = {**os.environ, "PYTHONPATH": str(tree)}
    run = tree_peak.measured([sys.executable, "-m", "rangekit", "-q", "process", str(copy)], env=env, cwd=copy.parent)
    if run["exit"]:
        raise SystemExit(f"{tree}: rangekit process {copy} failed (exit {run['exit']}):\n{run['stderr'][-3000:]}")
    return run


def _spread(values: list[float]) -> str:
    return f"{statistics.median(values):.2f} ({min(values):.2f}-{max(values):.2f})"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("session", type=Path)
    ap.add_argument("old_tree", type=Path)
    ap.add_argument("--new-tree", type=Path, default=ROOT)
    ap.add_argument("--pairs", type=int, default=5)
    ap.add_argument("--new-session", type=Path, default=None)
    args = ap.parse_args()
    if not (args.session / "session.json").is_file():
        raise SystemExit(f"{args.session}: not a session folder (no session.json)")
    if not (args.old_tree / "rangekit" / "__init__.py").is_file():
        raise SystemExit(f"{args.old_tree}: not a rangekit checkout (no rangekit/__init__.py)")
    trees = {"new": args.new_tree.resolve(), "old": args.old_tree.resolve()}
    copies = {}
    sessions = {"new": args.new_session or args.session, "old": args.session}
    for name in trees:
        copies[name] = sessions[name].with_name(f"{sessions[name].name}.{name}")
        if not copies[name].exists():
            shutil.copytree(sessions[name], copies[name])
    for name in trees:                                     # warm-up: numba's caches of each tree
        _run(trees[name], copies[name])
    runs: dict[str, list[dict]] = {"new": [], "old": []}
    for k in range(args.pairs):
        for name in trees:
            runs[name].append(_run(trees[name], copies[name]))
            r = runs[name][-1]
            print(f"pair {k + 1} {name}: {r['wall_s']:.1f} s wall, {r['cpu_s']:.1f} CPU-s, {r['peak_gb']:.2f} GB",
                  flush=True)
    print(f"\n{args.pairs} pairs, median (min-max):")
    for fig in FIGURES:
        new, old = [r[fig] for r in runs["new"]], [r[fig] for r in runs["old"]]
        print(f"  {fig}: new {_spread(new)}, old {_spread(old)}, new/old {_spread([a / b for a, b in zip(new, old)])}")
    for name in trees:
        acc = json.loads((copies[name] / "summary.json").read_text())["accuracy"]
        print(f"  {name} accuracy: observed RMS {acc['rms'] * 1e3:.4f} mm, p95 {acc['p95'] * 1e3:.4f} mm, completeness "
              f"{acc['completeness'] * 100:.2f}% (whole {acc.get('completeness_whole', float('nan')) * 100:.1f}%); "
              f"closed RMS {acc['watertight']['rms'] * 1e3:.3f} mm")
    return 0


if __name__ == "__main__":
    sys.exit(main())
