"""Does Open3D's Poisson let Python run beside it? (why rangekit._runtime.child runs it in a child process)

    PYTHONPATH=. python benchmarks/surface/bench_poisson_gil.py [--points 200000] [--depth 8]

Poisson (one thread) runs on a thread on a unit sphere of ``--points`` oriented points while this thread
counts loop iterations until it ends. A call that released the GIL would let the loop run millions of
times; Open3D's holds it, and the loop barely starts. Printed: Poisson's seconds and the iterations.
"""

from __future__ import annotations

import argparse
import threading
import time

import numpy as np
import open3d as o3d


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--points", type=int, default=200_000)
    ap.add_argument("--depth", type=int, default=8)
    args = ap.parse_args()
    p = np.random.default_rng(0).normal(size=(args.points, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p))
    cloud.normals = o3d.utility.Vector3dVector(p)
    seconds = {}

    def poisson() -> None:
        t = time.perf_counter()
        o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(cloud, depth=args.depth, n_threads=1)
        seconds["poisson"] = time.perf_counter() - t

    worker = threading.Thread(target=poisson)
    worker.start()
    n = 0
    while worker.is_alive():
        n += 1
    worker.join()
    print(f"Poisson depth {args.depth} on {args.points:,} points: {seconds['poisson']:.1f} s; a Python loop beside "
          f"it ran {n:,} iterations ({n / seconds['poisson']:,.0f} per second)")


if __name__ == "__main__":
    main()
