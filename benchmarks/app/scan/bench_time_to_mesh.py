"""The time a person waits for the mesh (issue 51): ``rangekit scan --realtime`` of the default object, run as a
user runs it (the CLI, a process of its own), side by side for two trees in one run, pairs in turn.

    PYTHONPATH=. python benchmarks/app/scan/bench_time_to_mesh.py --old /work/wt-302 --pairs 2 [--out /tmp/ttm]
    PYTHONPATH=. python benchmarks/app/scan/bench_time_to_mesh.py --old /work/wt-302 --rows old new new-png

Each run's times come from the files it writes, the same way for any version (an old tree's scan has no
``events.jsonl`` timestamps): the start is when the process is launched; the last frame is the newest frame file's
mtime in the view folders; the preview and the mesh are ``preview.ply``'s and ``mesh.ply``'s mtimes. Printed per
run (one JSON line, as it ends): start -> mesh.ply, last frame -> mesh.ply, last frame -> preview.ply, the process's
wall and CPU seconds (user + system, children included), the observed mesh's RMS and completeness against the truth
(summary.json), the load average before and after. Then the medians per row and the ratio of each row's start ->
mesh to the first row's, pair by pair.

Rows: ``old`` the ``--old`` tree's scan; ``new`` this tree's; ``new-png`` this tree's with ``--frames png`` (the
frame format of old trees: a faster frame format is its own row, not part of a code speed-up). A pair runs its
rows in turn, the order reversed every other pair (the machine's load drifts). ``--no-report`` on every side (the
report comes after mesh.ply). On this tree ``--realtime`` models the triggered rig (docs/simulator.md); an old tree's
is free-running with the rig file's 0.1 s pattern delay: the frames are the same bytes.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[3]


def _mtime(path: Path) -> float | None:
    return path.stat().st_mtime if path.exists() else None


def _last_frame(folder: Path) -> float | None:
    times = [p.stat().st_mtime for p in folder.glob("view_*/[0-9]*") if p.is_file()]
    return max(times) if times else None


def run_one(tree: Path, out: Path, extra: list[str]) -> dict:
    """One scan of ``tree`` into ``out`` (removed first): its times (module doc)."""
    if out.exists():
        shutil.rmtree(out)
    cmd = [sys.executable, "-m", "rangekit", "scan", "--realtime", "--no-report", "-q", "--out", str(out), *extra]
    env = {**os.environ, "PYTHONPATH": str(tree)}
    load0 = os.getloadavg()[0]
    t0 = time.time()
    proc = subprocess.Popen(cmd, cwd=tree, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.time() - t0
    err = proc.stderr.read().decode(errors="replace")
    proc.stderr.close()
    code = os.waitstatus_to_exitcode(status)
    last, preview, mesh = _last_frame(out), _mtime(out / "preview.ply"), _mtime(out / "mesh.ply")
    acc = {}
    if (out / "summary.json").is_file():
        acc = json.loads((out / "summary.json").read_text()).get("accuracy") or {}

    def span(a, b):
        return None if a is None or b is None else round(b - a, 2)

    return {"tree": str(tree), "extra": extra, "exit": code, "start_to_mesh_s": span(t0, mesh),
            "last_frame_to_mesh_s": span(last, mesh), "last_frame_to_preview_s": span(last, preview),
            "start_to_last_frame_s": span(t0, last), "wall_s": round(wall, 2),
            "cpu_s": round(usage.ru_utime + usage.ru_stime, 2),
            "rms_mm": None if "rms" not in acc else round(acc["rms"] * 1e3, 4),
            "completeness": acc.get("completeness"), "load_before": round(load0, 2),
            "load_after": round(os.getloadavg()[0], 2), **({"stderr": err[-400:]} if code else {})}


ROWS = {"old": ("old", []), "new": ("new", []), "new-png": ("new", ["--frames", "png"])}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--old", type=Path, required=True, help="the tree to compare with (e.g. /work/wt-302)")
    parser.add_argument("--new", type=Path, default=HERE, help="this tree (default: the one holding this script)")
    parser.add_argument("--pairs", type=int, default=2)
    parser.add_argument("--rows", nargs="+", choices=tuple(ROWS), default=["old", "new"])
    parser.add_argument("--out", type=Path, default=Path("/tmp/bench_time_to_mesh"))
    args = parser.parse_args()
    trees = {"old": args.old.resolve(), "new": args.new.resolve()}
    runs: dict[str, list[dict]] = {row: [] for row in args.rows}
    for pair in range(args.pairs):
        order = args.rows if pair % 2 == 0 else args.rows[::-1]
        for row in order:
            side, extra = ROWS[row]
            res = run_one(trees[side], args.out / f"{row}_{pair}", extra)
            runs[row].append(res)
            print(json.dumps({"pair": pair, "row": row, **res}), flush=True)
    first = args.rows[0]
    print(f"\nmedians over {args.pairs} pair(s):")
    for row in args.rows:
        cols = {}
        for key in ("start_to_mesh_s", "last_frame_to_mesh_s", "last_frame_to_preview_s", "wall_s", "cpu_s",
                    "rms_mm", "completeness"):
            values = [r[key] for r in runs[row] if r[key] is not None]
            cols[key] = round(statistics.median(values), 4) if values else None
        ratios = [round(r["start_to_mesh_s"] / f["start_to_mesh_s"], 3) for r, f in zip(runs[row], runs[first])
                  if r["start_to_mesh_s"] and f["start_to_mesh_s"]]
        print(json.dumps({"row": row, **cols, f"start_to_mesh / {first} (pairs)": ratios}), flush=True)


if __name__ == "__main__":
    main()
