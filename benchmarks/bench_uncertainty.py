"""Predicted per-point sigma against the observed error on single simulated views (issue 18, point 4).

    PYTHONPATH=. python benchmarks/bench_uncertainty.py [--objects sphere bunny] [--angle 0] [--seed 0]
                                                       [--patterns hybrid]

For each object: one view of the default simulated rig (the object's default scene, turntable angle
``--angle`` radians) captured with ``--patterns``, reconstructed by :func:`rangekit.app.reconstruct.reconstruct_view`
(decode, triangulate, edge filter: what ``rangekit scan`` does per view) with the predicted sigma of every
point (:mod:`rangekit.coded.uncertainty`). The observed error of a point is its offset from the exact
surface point of its pixel (the simulator's ground-truth ``xyz``) along the camera ray, on the object's
pixels. Points are split into deciles of predicted sigma; each row prints the decile's sigma range, the
RMS predicted sigma, the RMS observed error and their ratio (acceptance: every ratio in 0.8..1.2).
The table is quoted in docs/metrology.md ("Predicted uncertainty").
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from rangekit.app.reconstruct import reconstruct_view
from rangekit.camera import pixel_rays
from rangekit.coded.patterns import make_pattern_spec
from rangekit.geometry import transform_vectors
from rangekit.sim import SimRig, default_scene


def decile_table(sigma: np.ndarray, error: np.ndarray) -> list[tuple[float, float, float, float, int]]:
    """(low, high, RMS predicted, RMS observed, n) per decile of predicted ``sigma`` (metres)."""
    q = np.quantile(sigma, np.linspace(0, 1, 11))
    k = np.clip(np.searchsorted(q, sigma, side="right") - 1, 0, 9)
    return [(q[i], q[i + 1], float(np.sqrt(np.mean(sigma[k == i] ** 2))), float(np.sqrt(np.mean(error[k == i] ** 2))),
             int(np.count_nonzero(k == i))) for i in range(10)]


def measure(obj: str, angle: float, seed: int, patterns: str) -> tuple[np.ndarray, np.ndarray]:
    """(predicted sigma, observed along-ray error), metres, of the object's reconstructed points."""
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
    return rec.sigma[on].astype(np.float64), error[on]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--objects", nargs="+", default=["sphere", "bunny"])
    ap.add_argument("--angle", type=float, default=0.0, help="turntable angle, radians")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--patterns", default="hybrid", choices=["hybrid", "phase", "graycode"])
    args = ap.parse_args()
    worst = 0.0
    for obj in args.objects:
        t0 = time.perf_counter()
        sigma, error = measure(obj, args.angle, args.seed, args.patterns)
        print(f"{obj}: {sigma.size} points, median sigma {np.median(sigma) * 1e3:.4f} mm, RMS error "
              f"{np.sqrt(np.mean(error ** 2)) * 1e3:.4f} mm ({time.perf_counter() - t0:.0f} s)")
        print("  decile  sigma range (mm)     predicted RMS  observed RMS  observed/predicted")
        for i, (lo, hi, p, o, _) in enumerate(decile_table(sigma, error)):
            worst = max(worst, abs(o / p - 1))
            print(f"  {i + 1:6d}  {lo * 1e3:.4f} - {hi * 1e3:.4f}    {p * 1e3:.4f} mm     {o * 1e3:.4f} mm     {o / p:.3f}")
    print(f"largest |observed / predicted - 1| over the deciles: {worst:.3f} (acceptance: <= 0.2)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
