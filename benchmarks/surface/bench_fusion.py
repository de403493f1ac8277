"""TSDF fusion speed at full resolution: 12 simulated 1280x1024 views of the ``lumpy`` object.

Target (formerly an assert in tests/surface/test_mesh.py): ``tsdf_fuse`` of the 12 views in under 10 s on a
2-core machine. ``tsdf_fuse`` wraps Open3D's ``UniformTSDFVolume``, so the comparison printed is with
and without the watertight closing (what :func:`make_watertight` adds to Open3D's own work).

    .venv/bin/python benchmarks/surface/bench_fusion.py

Prints the times and exits non-zero if the target is missed; ``--markdown`` prints docs/benchmarks.md's
table instead (a ``make docs-figures`` block, exit 0).
"""

from __future__ import annotations

import dataclasses
import sys
import time

import numpy as np

TARGET_S = 10.0


def main() -> int:
    from rangekit.geometry import apply_T, compose, invert_T
    from rangekit.sim import SimRig, default_rig, default_scene
    from rangekit.surface.fusion import tsdf_fuse

    rig = default_rig()
    rig = dataclasses.replace(rig, cameras=(rig.camera.resized(1280, 1024),))
    sim = SimRig(default_scene("lumpy", with_table=False), rig)
    views = []
    for k in range(12):
        angle = np.radians(30.0 * k)
        sim.turntable.rotate_to(angle)
        truth = sim.ground_truth()
        camera = rig.camera.with_pose(compose(invert_T(rig.T_world_rotated(angle)), rig.camera.T_world_cam))
        depth = np.where(truth.hit, apply_T(rig.camera.T_cam_world, truth.xyz.reshape(-1, 3))[:, 2]
                         .reshape(truth.hit.shape), np.nan)
        views.append((depth, None, camera))
    t = time.perf_counter()
    mesh = tsdf_fuse(views)
    seconds = time.perf_counter() - t
    t = time.perf_counter()
    open_mesh = tsdf_fuse(views, watertight=False)
    seconds_open = time.perf_counter() - t
    if "--markdown" in sys.argv[1:]:
        print("| run | time | vertices |\n|---|---|---|")
        print(f"| `tsdf_fuse`, watertight | {seconds:.1f} s | {len(mesh.vertices):,} |")
        print(f"| `tsdf_fuse(watertight=False)` | {seconds_open:.1f} s | {len(open_mesh.vertices):,} |")
        print(f"\nTarget < {TARGET_S:.0f} s: {'met' if seconds < TARGET_S else 'MISSED'}.")
        return 0
    print(f"tsdf_fuse(12 views, 1280x1024): {seconds:.2f} s, {len(mesh.vertices):,} vertices, watertight "
          f"{mesh.is_watertight}; without closing: {seconds_open:.2f} s, {len(open_mesh.vertices):,} vertices")
    print(f"target < {TARGET_S} s: {'met' if seconds < TARGET_S else 'MISSED'}")
    return 0 if seconds < TARGET_S else 1


if __name__ == "__main__":
    sys.exit(main())
