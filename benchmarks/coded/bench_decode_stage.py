"""The decode stage of ``rangekit process``, sub-step by sub-step, in CPU seconds (for process's speed targets).

    PYTHONPATH=. python benchmarks/coded/bench_decode_stage.py SESSION [--views N] [--repeat R] [--profile]
                                                               [--markdown]

SESSION is a session folder (e.g. one made by ``rangekit scan --out S --no-process``); it is not changed
(each run decodes copies of its views' frames in a temporary folder, with no cache). For each of the views
the stage's own function, :func:`rangekit.app.process.view_cache.view_cloud`, runs with every sub-step's function
wrapped in a ``time.process_time()`` counter (user + sys of the whole process, so PNG loading on two
threads counts both threads):

    png        reading the view's frames (``read_stack``: headers + PNG inflate on 2 threads)
    decode     ``rangekit.coded.decode.decode``
    triangulate  camera rays against projector planes / rays
    filter+normals  ``discontinuity_mask`` + ``range_normals`` (or their fused pass)
    sigma      per-point predicted sigma (``point_sigma``)
    write      ``cloud.ply``, ``maps.npz``, ``cloud.json`` with the SHA-256s
    other      the rest of ``view_cloud`` (masks, depth map, table cut, colours)

CPU seconds, not wall: the machine may be shared (the stage's wall clock is printed too). The views run
through ``view_clouds`` as ``rangekit process`` runs them (the next view's frames are read while one
decodes; with ``--profile``, or a tree without it, one ``view_cloud`` at a time). ``--repeat`` runs the whole stage R times and reports the
minimum per sub-step. ``--markdown`` prints docs/benchmarks.md's table (a ``make docs-figures`` block).
``--code TREE`` times another checkout. ``--profile`` prints a cProfile (CPU-time) of the second view (the first fills the per-rig caches).
"""

from __future__ import annotations

import argparse
import os
import cProfile
import pstats
import shutil
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]  # the repo (this is benchmarks/ROOM/SCRIPT.py)
# --code TREE: time another checkout's rangekit (before/after), e.g. --code ../main
CODE = Path(sys.argv[sys.argv.index("--code") + 1]) if "--code" in sys.argv[:-1] else ROOT
sys.path.insert(0, str(CODE))

from rangekit import __version__  # noqa: E402
from rangekit.coded import reconstruct as rec_mod  # noqa: E402
from rangekit.app.process import view_cache as vc_mod  # noqa: E402
from rangekit.coded.reconstruct import EDGE_MARGIN_PX  # noqa: E402
from rangekit.formats.sessions.session import Session  # noqa: E402
from rangekit.geometry import invert_T  # noqa: E402

#: --serial: one view_cloud at a time (no read-ahead), to compare
SERIAL = "--serial" in sys.argv

#: sub-step -> (module, attribute) pairs wrapped by the counter (missing attributes are skipped)
STEPS = {
    "png": [(vc_mod, "read_stack")],
    "decode": [(rec_mod, "decode")],
    "triangulate": [(rec_mod, "triangulate")],
    "filter+normals": [(rec_mod, "discontinuity_mask"), (rec_mod, "range_normals"), (rec_mod, "filter_range_map")],
    "sigma": [(rec_mod, "point_sigma")],
    "write": [(vc_mod, "save_cloud"), (vc_mod, "atomic_save_npz"), (vc_mod, "atomic_write_json"),
              (vc_mod, "save_maps")],
}


def _wrap(totals: dict, step: str, fn):
    def wrapped(*args, **kwargs):
        t = time.process_time()
        try:
            return fn(*args, **kwargs)
        finally:
            totals[step] += time.process_time() - t
    return wrapped


def _copy_session(src: Path, dst: Path, n_views: int) -> None:
    for name in ("session.json", "rig.json", "patterns.json"):
        if (src / name).exists():
            shutil.copy2(src / name, dst / name)
    for v in sorted(src.glob("view_*"))[:n_views]:
        (dst / v.name).mkdir()
        for f in v.iterdir():
            if f.is_file() and f.name not in ("cloud.json", "cloud.ply", "maps.npz"):
                shutil.copy2(f, dst / v.name / f.name)


def run_stage(folder: Path, n_views: int, profile: bool) -> tuple[dict, float, int]:
    """(CPU-s per sub-step, CPU-s of the whole stage, points) for the first ``n_views`` views, no cache."""
    session = Session.load(folder)
    views = session.done_views[:n_views]
    rig, spec, full_scale = session.rig, session.pattern, session.capture.full_scale
    T_table_world = invert_T(rig.T_world_table) if rig.T_world_table is not None else None
    settings = {"rangekit": __version__, "method": "auto", "table_margin": 0.002, "edge_margin_px": EDGE_MARGIN_PX,
                "pattern": spec.to_dict()["method"], "full_scale": full_scale,
                "projector_response": None if rig.projector_response is None else rig.projector_response.to_dict()}
    totals = {k: 0.0 for k in STEPS}
    saved = []
    for step, targets in STEPS.items():
        for mod, name in targets:
            if hasattr(mod, name):
                saved.append((mod, name, getattr(mod, name)))
                setattr(mod, name, _wrap(totals, step, getattr(mod, name)))
    points = 0
    try:
        t0, w0 = time.process_time(), time.perf_counter()
        if profile or SERIAL or not hasattr(vc_mod, "view_clouds"):
            for k, v in enumerate(views):
                if profile and k == min(1, len(views) - 1):
                    pr = cProfile.Profile(time.process_time)
                    cloud, _ = pr.runcall(vc_mod.view_cloud, v, spec, rig, settings, full_scale, T_table_world, 0.002)
                    pstats.Stats(pr).sort_stats(os.environ.get("BENCH_SORT", "cumulative")).print_stats(45)
                else:
                    cloud, _ = vc_mod.view_cloud(v, spec, rig, settings, full_scale, T_table_world, 0.002)
                points += len(cloud)
        else:  # as `rangekit process` runs it: the next view's frames read while this one decodes
            for cloud, _ in vc_mod.view_clouds(views, spec, rig, settings, full_scale, T_table_world, 0.002):
                points += len(cloud)
        total, wall = time.process_time() - t0, time.perf_counter() - w0
    finally:
        for mod, name, fn in saved:
            setattr(mod, name, fn)
    totals["other"] = total - sum(totals.values())
    totals["wall"] = wall
    return totals, total, points


LABELS = {"png": "PNG loading", "decode": "decoding (hybrid, incl. numba's cache load once)",
          "triangulate": "triangulation (ray-ray)", "sigma": "predicted sigma", "filter+normals": "filter + normals",
          "write": "writing the cache", "other": "the rest (masks, depth map, table cut)"}
TARGET_CPU_S = 8.0


def markdown(best: dict, total: float, points: int, a) -> str:
    """docs/benchmarks.md's table: each sub-step's CPU seconds, the stage's CPU and wall, the target."""
    mode = "`--serial`" if a.serial else "read-ahead"
    rows = [f"| sub-step, {a.views} views | CPU s ({mode}, min of {a.repeat}) |", "|---|---|"]
    rows += [f"| {LABELS.get(k, k)} | {v:.2f} |" for k, v in best.items() if k != "wall"]
    rows += [f"| **stage, CPU s** | **{total:.2f}** |", f"| **stage, wall s** | {best['wall']:.2f} |", "",
             f"{points:,} points. Target {TARGET_CPU_S:g} CPU-s: {'met' if total <= TARGET_CPU_S else 'not met'} "
             "in this run."]
    return "\n".join(rows)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("session", type=Path)
    ap.add_argument("--views", type=int, default=12)
    ap.add_argument("--repeat", type=int, default=1)
    ap.add_argument("--profile", action="store_true")
    ap.add_argument("--serial", action="store_true", help="no read-ahead of the next view's frames")
    ap.add_argument("--code", type=Path, default=ROOT, help="rangekit tree to time (default: this one)")
    ap.add_argument("--markdown", action="store_true", help="print docs/benchmarks.md's table")
    a = ap.parse_args()
    best, best_total, points = None, float("inf"), 0
    with tempfile.TemporaryDirectory(prefix="bench_decode_stage_") as tmp:
        for r in range(a.repeat):
            work = Path(tmp) / f"run{r}"
            work.mkdir()
            _copy_session(a.session, work, a.views)
            totals, total, points = run_stage(work, a.views, a.profile and r == 0)
            best = totals if best is None else {k: min(best[k], totals[k]) for k in totals}
            best_total = min(best_total, total)
            shutil.rmtree(work)
    if a.markdown:
        print(markdown(best, best_total, points, a))
        return
    print(f"rangekit from {CODE}")
    print(f"decode stage of {a.session}: {a.views} views, {points:,} points, min of {a.repeat} run(s), CPU-s")
    for k, v in best.items():
        if k != "wall":
            print(f"  {k:<15} {v:6.2f}")
    print(f"  {'total':<15} {best_total:6.2f}")
    print(f"  {'wall s':<15} {best['wall']:6.2f}  (the stage's wall clock, loaded machine or not)")


if __name__ == "__main__":
    main()
