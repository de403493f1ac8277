"""The observed mesh's last steps on a processed session, unrefined, every edge halved and at the refinement's
threshold: CPU seconds of the refinement, the writing with its summary entry and the evaluator, and the accuracy.

    OPENBLAS_NUM_THREADS=1 PYTHONPATH=. .venv/bin/python benchmarks/surface/bench_refine_cost.py SESSION [--runs 3]

``SESSION``: a simulated coded-light session processed once (its ``merged.ply``; ``rangekit scan --out S``). Its
Poisson surface is made again as processing makes it (the merged cloud's sample, depth 8, one thread), cut by the
observed rule, then each variant is refined (:func:`rangekit.surface.refine.refine_to_points`), written
(:func:`rangekit.app.process.fused_outputs.save_one`) and measured by the session's evaluator. Printed: one
Markdown row per variant, the least CPU seconds of ``--runs`` runs of each step (docs/benchmarks.md, issue 51).
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

from scipy.spatial import cKDTree

from rangekit.app.process.fused_outputs import save_one
from rangekit.app.process.options import POISSON_POINTS
from rangekit.app.scan.truth import session_evaluator
from rangekit.formats.clouds import load_cloud
from rangekit.formats.sessions.session import load_session
from rangekit.surface.cloud import PointCloud
from rangekit.surface.fusion import poisson_input, poisson_surfaces
from rangekit.surface.mesh import TriangleMesh
from rangekit.surface.observed import observed_rule
from rangekit.surface.refine import SPLIT_SAG, refine_to_points


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("session", type=Path)
    ap.add_argument("--runs", type=int, default=3)
    args = ap.parse_args()
    merged = load_cloud(args.session / "merged.ply")
    step = max(1, -(-len(merged) // POISSON_POINTS))
    sample = PointCloud(merged.points[::step].copy(), merged.colours[::step].copy(), merged.normals[::step].copy())
    full, _ = poisson_surfaces(sample, depth=8, n_threads=1)
    used = poisson_input(sample)
    P, N = sample.points[used], sample.normals[used]
    cut = observed_rule(P).observed_part(full)
    tree = cKDTree(P)
    session = load_session(args.session)
    evaluate, angles = session_evaluator(session), [v.angle for v in session.views]
    evaluate.prepare(angles)
    out = Path(tempfile.mkdtemp())
    variants = {"unrefined (302926b)": None, "every edge halved": 0.0, f"sag {SPLIT_SAG * 1e6:g} um": SPLIT_SAG}
    least: dict = {}
    for _ in range(args.runs):
        for name, sag in variants.items():
            mesh = TriangleMesh(cut.vertices, cut.triangles, cut.vertex_colours)   # nothing cached
            t0 = time.process_time()
            mesh = mesh if sag is None else refine_to_points(mesh, P, N, tree=tree, sag=sag)
            t1 = time.process_time()
            save_one(out, mesh, "poisson", "mesh.ply")
            t2 = time.process_time()
            acc = evaluate(mesh, angles).accuracy
            t3 = time.process_time()
            times = (t1 - t0, t2 - t1, t3 - t2, t3 - t0)
            least[name] = (tuple(min(a, b) for a, b in zip(least[name][0], times)) if name in least else times,
                           (len(mesh.vertices), acc.rms, acc.p95))
    print("| observed mesh | vertices | RMS / p95 | refine | write + entry | evaluator | together |")
    print("|---|---|---|---|---|---|---|")
    for name, (t, (v, rms, p95)) in least.items():
        print(f"| {name} | {v:,} | {rms * 1e3:.4f} / {p95 * 1e3:.4f} mm | {t[0]:.2f} | {t[1]:.2f} | {t[2]:.2f} | {t[3]:.2f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
