"""Open3D's screened Poisson on one thread and on two, on a processed scan's merged cloud (for process's speed).

    PYTHONPATH=. python benchmarks/surface/bench_poisson_threads.py SESSION [--runs 2]

SESSION is a processed session folder (``merged.ply``); the cloud is subsampled as ``rangekit process``
does (at most about 400k points) and meshed at depth 9 with ``n_threads`` 1 and 2, ``--runs`` times each.
Prints CPU and wall seconds per run and a hash of each mesh (vertices, triangles, densities): runs on one
thread give the same hash; on two threads the hash changes from run to run, which is why
``rangekit process`` keeps Poisson on one thread (a resumed scan gives the same mesh bytes).
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import time

import numpy as np


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("session")
    ap.add_argument("--runs", type=int, default=2)
    args = ap.parse_args()
    import open3d as o3d

    from rangekit.formats.clouds import load_cloud

    c = load_cloud(f"{args.session}/merged.ply")
    step = max(1, len(c) // 400_000)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(c.points[::step]))
    pcd.normals = o3d.utility.Vector3dVector(c.normals[::step].astype(np.float64))
    print(f"{len(c.points[::step]):,} points, depth 9")
    hashes = {1: set(), 2: set()}
    for threads in [1, 2] * args.runs:
        c0, w0 = time.process_time(), time.perf_counter()
        m, dens = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(pcd, depth=9, n_threads=threads)
        cpu, wall = time.process_time() - c0, time.perf_counter() - w0
        V, F = np.asarray(m.vertices), np.asarray(m.triangles)
        h = hashlib.sha256(V.tobytes() + F.tobytes() + np.asarray(dens).tobytes()).hexdigest()[:16]
        hashes[threads].add(h)
        print(f"n_threads={threads}: {cpu:.2f} CPU-s, {wall:.2f} s wall, {len(V):,} vertices, mesh {h}", flush=True)
    for threads, hs in hashes.items():
        print(f"n_threads={threads}: {'the same mesh every run' if len(hs) == 1 else f'{len(hs)} different meshes'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
