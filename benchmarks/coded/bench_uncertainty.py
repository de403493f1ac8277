"""Predicted per-point sigma against the observed error on single simulated views (docs/metrology.md's uncertainty).

    PYTHONPATH=. python benchmarks/coded/bench_uncertainty.py [--objects sphere bunny] [--angles 0 1 2.5 4] [--seed 0]
                                                             [--patterns hybrid]

For each object and turntable angle (radians): one view of the default simulated rig (the object's default
scene) captured with ``--patterns``, reconstructed by :func:`rangekit.coded.reconstruct.reconstruct_view`
(decode, triangulate, edge filter: what ``rangekit scan`` does per view) with the predicted sigma of every
point (:mod:`rangekit.coded.uncertainty`). The observed error of a point is its offset from the exact
surface point of its pixel (the simulator's ground-truth ``xyz``) along the camera ray, on the object's
pixels. The points of all angles are split into deciles of predicted sigma; each row prints the decile's
sigma range, the RMS predicted sigma, the RMS observed error and their ratio (acceptance: every ratio in
0.8..1.2), then the same ratio for the points away from depth edges (``inside``: farther than
:data:`rangekit.sim.truth.view_errors.EDGE_PX` pixels from a silhouette or depth jump of the true depth map,
:func:`rangekit.sim.truth.view_errors.depth_edges`), and the share of edge points in the decile.
The table is quoted in docs/metrology.md ("Predicted uncertainty").
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from rangekit.coded.reconstruct import reconstruct_view
from rangekit.camera import pixel_rays
from rangekit.coded.patterns import make_pattern_spec
from rangekit.geometry import transform_vectors
from rangekit.sim import SimRig, default_scene
from rangekit.sim.truth.view_errors import depth_edges


def measure(obj: str, angle: float, seed: int, patterns: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(predicted sigma, observed along-ray error) in metres, and near a true depth edge (bool), of the
    object's reconstructed points."""
    sim = SimRig(default_scene(obj), seed=seed)
    sim.turntable.rotate_to(angle)
    rig = sim.rig
    spec = make_pattern_spec(patterns, rig.projector.size)
    images = sim.capture_sequence(list(spec.frames()))
    truth = sim.ground_truth()
    rec = reconstruct_view(images, spec, rig.camera, rig.projector, response=rig.projector_response)
    if rec.sigma is None:
        raise SystemExit(f"--patterns {patterns}: this decoder predicts no sigma")
    rays = transform_vectors(rig.camera.T_world_cam, pixel_rays(rig.camera).reshape(-1, 3)).reshape(truth.xyz.shape)
    rays /= np.linalg.norm(rays, axis=2, keepdims=True)
    on = np.isfinite(rec.sigma) & truth.hit & (truth.object_id == 0)
    error = np.sum((rec.triangulated.xyz - truth.xyz) * rays, axis=2)
    return rec.sigma[on].astype(np.float64), error[on], depth_edges(truth.depth)[on]


def markdown(table: dict) -> None:
    """docs/metrology.md's table (a ``make docs-figures`` block): per decile and object the predicted and
    observed RMS (mm), their ratio, the ratio away from depth edges; the last object's edge share; then
    the acceptance sentence (every decile within 20%)."""
    last = list(table)[-1]
    head = [f"{o} {c}" for o in table for c in ("sigma (mm)", "observed (mm)", "obs / pred", "inside")]
    print("| decile | " + " | ".join(head) + f" | {last} edge |")
    print("|---|" + "---|" * (len(head) + 1))
    for i in range(10):
        cells = [f"{p * 1e3:.4f} | {o * 1e3:.4f} | {r:.2f} | {ri:.2f}" for p, o, r, ri, _ in (table[o][i] for o in table)]
        print(f"| {i + 1} | " + " | ".join(cells) + f" | {table[last][i][4]:.1%} |")
    parts = []
    for obj, rows in table.items():
        r = [row[2] for row in rows]
        parts.append(f"the {obj} within {max(abs(x - 1) for x in r):.0%} ({min(r):.2f}-{max(r):.2f})")
    ok = all(abs(row[2] - 1) <= 0.2 for rows in table.values() for row in rows)
    print(f"\n(sigma and observed are RMS over the decile.) {'Every object meets' if ok else 'NOT every object meets'} "
          f"the 20% acceptance in every decile: {', '.join(parts)}.")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--objects", nargs="+", default=["sphere", "bunny"])
    ap.add_argument("--angles", type=float, nargs="+", default=[0.0, 1.0, 2.5, 4.0], help="turntable angles, rad")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--patterns", default="hybrid", choices=["hybrid", "phase", "graycode"])
    ap.add_argument("--markdown", action="store_true", help="print docs/metrology.md's decile table")
    args = ap.parse_args()
    worst = {"all": 0.0, "inside": 0.0}
    table = {}  # object -> per decile (predicted, observed, obs/pred, inside obs/pred, edge share)
    for obj in args.objects:
        t0 = time.perf_counter()
        parts = [measure(obj, a, args.seed, args.patterns) for a in args.angles]
        sigma, error, edge = (np.concatenate(p) for p in zip(*parts))
        say = (lambda *a, **k: None) if args.markdown else print
        say(f"{obj}, angles {' '.join(f'{a:g}' for a in args.angles)}: {sigma.size} points, median sigma "
            f"{np.median(sigma) * 1e3:.4f} mm, RMS error {np.sqrt(np.mean(error ** 2)) * 1e3:.4f} mm "
            f"({time.perf_counter() - t0:.0f} s)")
        table[obj] = []
        say("  decile  sigma range (mm)   predicted RMS  observed RMS  obs/pred  inside obs/pred  edge share")
        q = np.quantile(sigma, np.linspace(0, 1, 11))
        k = np.clip(np.searchsorted(q, sigma, side="right") - 1, 0, 9)
        for i in range(10):
            m, mi = k == i, (k == i) & ~edge
            p, o = np.sqrt(np.mean(sigma[m] ** 2)), np.sqrt(np.mean(error[m] ** 2))
            ri = np.sqrt(np.mean(error[mi] ** 2) / np.mean(sigma[mi] ** 2))
            worst["all"], worst["inside"] = max(worst["all"], abs(o / p - 1)), max(worst["inside"], abs(ri - 1))
            table[obj].append((p, o, o / p, ri, float(np.mean(edge[m]))))
            say(f"  {i + 1:6d}  {q[i] * 1e3:.4f} - {q[i + 1] * 1e3:.4f}  {p * 1e3:.4f} mm      {o * 1e3:.4f} mm     "
                  f"{o / p:.3f}     {ri:.3f}            {np.mean(edge[m]):.1%}")
    if args.markdown:
        markdown(table)
        return 0
    print(f"largest |observed / predicted - 1| over the deciles: {worst['all']:.3f} all points, "
          f"{worst['inside']:.3f} away from depth edges (acceptance: <= 0.2)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
