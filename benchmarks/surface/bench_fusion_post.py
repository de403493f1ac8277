"""CPU seconds of the fusion's work around Open3D's Poisson call, on a processed session's merged cloud.

Poisson (depth 9, one thread) runs once on the 400k-point sample ``rangekit process`` fuses; then, the
minimum of ``--repeat`` runs: ``split_observed`` (the observed mesh, ``make_watertight``, the flags), the
two PLY bodies, and the two ``summary.json`` mesh entries (``mesh_info``, with ``is_watertight``). Prints
CPU seconds (``time.process_time``: the machine may be shared) and the SHA-256 of both PLY bodies: compare
them between two versions of the code (not with the session's ``mesh.ply``: merged.ply stores the normals
as float32, so Poisson's input here is not bit-identical to the run's). On the default 12-view session
(the speed work on rangekit process, loaded 2-core machine): 4.5 CPU-s around Poisson, against 7.4 before;
bodies unchanged.

    PYTHONPATH=. .venv/bin/python benchmarks/surface/bench_fusion_post.py SESSION [--repeat 3]
"""

from __future__ import annotations

import argparse
import hashlib
import time


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("session", help="a processed session folder (with merged.ply)")
    parser.add_argument("--repeat", type=int, default=3)
    args = parser.parse_args()

    from rangekit.app.process.fused_outputs import mesh_info
    from rangekit.formats.clouds import load_cloud
    from rangekit.formats.ply_write import mesh_ply_bytes
    from rangekit.surface.cloud import PointCloud
    from rangekit.surface.fusion import _poisson_surface
    from rangekit.surface.observed import split_observed
    from rangekit._runtime.threads import one_blas_thread

    merged = load_cloud(f"{args.session}/merged.ply")
    step = max(1, len(merged) // 400_000)
    sample = PointCloud(merged.points[::step], merged.colours[::step], merged.normals[::step])
    best: dict[str, float] = {}
    with one_blas_thread():
        c = time.process_time()
        surface, full, used = _poisson_surface(sample, 9, 0.02, True, 1)
        best["poisson"] = time.process_time() - c
        for _ in range(args.repeat):
            c0 = time.process_time()
            fused = split_observed(full, used.points, closing=surface)
            c1 = time.process_time()
            bodies = [mesh_ply_bytes(fused.observed), mesh_ply_bytes(fused.watertight)]
            c2 = time.process_time()
            [mesh_info(m, "poisson", "x.ply") for m in (fused.observed, fused.watertight)]
            c3 = time.process_time()
            for name, s in (("split_observed", c1 - c0), ("ply bodies", c2 - c1), ("mesh_info x2", c3 - c2)):
                best[name] = min(best.get(name, float("inf")), s)
    for name, s in best.items():
        print(f"{name:16s} {s:6.2f} CPU-s")
    print("around Poisson  ", f"{sum(v for k, v in best.items() if k != 'poisson'):6.2f} CPU-s")
    for name, body in zip(("mesh.ply", "mesh_watertight.ply"), bodies):
        print(f"{name:20s} sha256 {hashlib.sha256(body).hexdigest()}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
