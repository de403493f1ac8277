"""What bounds "mesh.ply within 3 s of the last frame" (issue 51): the fusion's own time on a processed scan.

    PYTHONPATH=. python benchmarks/surface/bench_mesh_ply_bound.py SESSION [--tsdf]

SESSION is a processed simulated session (``merged.ply``, ``poses.json``, each view's cached ``maps.npz``).
Prints, one line each:

- Open3D's screened Poisson (as ``rangekit process`` calls it: one thread) at octree depth 8 and 7 on every k-th
  merged point, 700k (the default sample), 350k and 200k points: CPU and wall seconds, vertices. Its time is
  the depth's, hardly the points'.
- Two threads at depth 8 on the default sample, three runs: wall seconds and a hash of the vertices (it changes
  run to run: not deterministic, so a resumed scan would not give the same mesh).
- With ``--tsdf``: the streaming volume's route (the scan's :class:`rangekit.surface.block_volume.BlockVolume`
  at 0.6 and 0.4 mm voxels, every view integrated at its registered pose, marching cubes, then the observed cut
  and the refinement onto Poisson's sample as ``rangekit process`` does them): each step's wall seconds and the
  observed mesh against the simulator's truth (RMS, 95th percentile, completeness).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import time
from pathlib import Path

import numpy as np


def _sample(cloud, points: int):
    from rangekit.surface.cloud import PointCloud

    step = max(1, -(-len(cloud.points) // points))
    return PointCloud(cloud.points[::step].copy(), None, cloud.normals[::step].copy())


def _poisson(cloud) -> None:
    from rangekit.surface.fusion import poisson_surfaces

    for points in (700_000, 350_000, 200_000):
        sample = _sample(cloud, points)
        for depth in (8, 7):
            c0, w0 = time.process_time(), time.perf_counter()
            full, _ = poisson_surfaces(sample, depth=depth, n_threads=1)
            print(f"poisson {len(sample.points):>7,} points depth {depth}, 1 thread: "
                  f"{time.process_time() - c0:5.2f} CPU-s {time.perf_counter() - w0:5.2f} s, "
                  f"{len(full.vertices):,} vertices", flush=True)
    sample = _sample(cloud, 700_000)
    for _ in range(3):
        w0 = time.perf_counter()
        full, _ = poisson_surfaces(sample, depth=8, n_threads=2)
        print(f"poisson {len(sample.points):>7,} points depth 8, 2 threads: {time.perf_counter() - w0:5.2f} s, "
              f"vertices {hashlib.sha1(full.vertices.tobytes()).hexdigest()[:10]}", flush=True)


def _tsdf(folder: Path, cloud) -> None:
    from rangekit.app.process.register import evaluator_angles
    from rangekit.app.scan.truth import session_evaluator
    from rangekit.formats.sessions.session import load_session
    from rangekit.geometry import compose
    from rangekit.surface.block_volume import BlockVolume
    from rangekit.surface.fusion import poisson_input
    from rangekit.surface.mesh import mesh_from_open3d
    from rangekit.surface.observed import observed_rule
    from rangekit.surface.refine import REFINE_NEIGHBOURS, refine_to_points

    session = load_session(folder)
    camera = session.rig.camera
    poses = [np.array(v["T_world_view"]) for v in json.loads((folder / "poses.json").read_text())["views"]]
    depths = [np.load(folder / f"view_{k:03d}" / "maps.npz")["depth"] for k in range(len(poses))]
    evaluate = session_evaluator(session)
    angles = evaluator_angles(session.views, multi_pass=False)
    sample = _sample(cloud, 700_000)
    used = poisson_input(sample)
    for voxel in (0.0006, 0.0004):
        w0 = time.perf_counter()
        volume = BlockVolume(voxel)
        for depth, T in zip(depths, poses):
            volume.integrate(depth, camera.with_pose(compose(T, camera.T_world_cam)))
        w1 = time.perf_counter()
        full = mesh_from_open3d(volume.mesh())
        w2 = time.perf_counter()
        rule = observed_rule(sample.points[used])
        w3 = time.perf_counter()
        mesh, d, idx = rule.observed_near(full, min(REFINE_NEIGHBOURS, rule.tree.n))
        mesh = refine_to_points(mesh, rule.tree.data, sample.normals[used], tree=rule.tree, near=(d, idx))
        w4 = time.perf_counter()
        a = evaluate(mesh, angles).accuracy
        print(f"tsdf {voxel * 1e3:.1f} mm voxels: integrate {w1 - w0:.2f} s, marching cubes {w2 - w1:.2f} s, "
              f"observed rule {w3 - w2:.2f} s, cut and refine {w4 - w3:.2f} s; observed {len(mesh.vertices):,} "
              f"vertices, RMS {a.rms * 1e3:.4f} mm, p95 {a.p95 * 1e3:.4f} mm, completeness "
              f"{a.completeness * 100:.2f}%", flush=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("session", type=Path)
    ap.add_argument("--tsdf", action="store_true", help="also the streaming volume's route, against the truth")
    args = ap.parse_args()
    from rangekit.formats.clouds import load_cloud

    cloud = load_cloud(args.session / "merged.ply")
    print(f"{args.session}: {len(cloud.points):,} merged points", flush=True)
    _poisson(cloud)
    if args.tsdf:
        _tsdf(args.session, cloud)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
