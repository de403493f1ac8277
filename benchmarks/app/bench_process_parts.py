"""The small measurements behind rangekit's thread and caching choices (for rangekit process's speed), one process.

    PYTHONPATH=. .venv/bin/python benchmarks/app/bench_process_parts.py [SESSION]

1. ``apply_T`` (an (N, 3) @ (3, 3) product plus a translation) on 200k and 1.3M points: OpenBLAS on one
   thread and on two (CPU seconds, both threads counted), and numpy's einsum loop: why the CLI and
   processing run BLAS on one thread (:mod:`rangekit._runtime.threads`) and why ``geometry._rotate`` stays a matmul.
2. With a processed SESSION (its ``mesh.ply``): building Open3D's ray-casting scene of the mesh against one
   640x480 cast on it, why :func:`rangekit.surface.raycast.mesh_scene` keeps the scene per mesh.
"""

from __future__ import annotations

import sys
import time

import numpy as np
from threadpoolctl import threadpool_limits

from rangekit.geometry import apply_T


def _cpu_ms(f, reps: int) -> float:
    f()
    c0 = time.process_time()
    for _ in range(reps):
        f()
    return (time.process_time() - c0) / reps * 1e3


def main() -> int:
    rng = np.random.default_rng(0)
    T = np.eye(4)
    T[:3, :3] = np.linalg.qr(rng.standard_normal((3, 3)))[0]
    T[:3, 3] = rng.standard_normal(3)
    print("| points | BLAS, 1 thread | BLAS, 2 threads | einsum |")
    print("|---|---|---|---|")
    for n in (200_000, 1_310_720):
        P = rng.standard_normal((n, 3))
        reps = max(5, 4_000_000 // n)
        with threadpool_limits(limits=1, user_api="blas"):
            one = _cpu_ms(lambda: apply_T(T, P), reps)
        with threadpool_limits(limits=2, user_api="blas"):
            two = _cpu_ms(lambda: apply_T(T, P), reps)
            loop = _cpu_ms(lambda: np.einsum("ij,kj->ik", P, T[:3, :3]) + T[:3, 3], reps)
        print(f"| {n:,} | {one:.1f} CPU-ms | {two:.1f} CPU-ms | {loop:.1f} CPU-ms |")
    if len(sys.argv) > 1:
        import open3d as o3d

        from rangekit.rendering.snapshot import fit_camera
        from rangekit.camera import world_pixel_rays
        from rangekit.formats.meshes import load_mesh
        from rangekit.surface.raycast import raycasting_scene

        mesh = load_mesh(f"{sys.argv[1]}/mesh.ply")
        c = (mesh.vertices.min(axis=0) + mesh.vertices.max(axis=0)) / 2
        o, d = world_pixel_rays(fit_camera(mesh.vertices, azimuth=0.5, elevation=0.3, size=(640, 480)))
        rays = o3d.core.Tensor(np.concatenate([o - c, d], axis=1).astype(np.float32))
        builds, casts = [], []
        for _ in range(3):
            w0 = time.perf_counter()
            scene = raycasting_scene(mesh.vertices - c, mesh.triangles)
            scene.cast_rays(rays)       # Open3D builds its BVH on the first cast
            w1 = time.perf_counter()
            scene.cast_rays(rays)
            w2 = time.perf_counter()
            builds.append((w1 - w0) - (w2 - w1))
            casts.append(w2 - w1)
        print(f"mesh of {len(mesh.triangles):,} triangles: scene build {min(builds):.3f} s, one 640x480 cast "
              f"{min(casts) * 1e3:.1f} ms ({min(builds) / min(casts):.0f}x)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
