"""Where the streamed mesh (the scan's sparse TSDF volume, issue 51) loses completeness, and what its steps after the
last view cost.

    PYTHONPATH=. python benchmarks/surface/bench_streamed_mesh.py SESSION [--voxels 0.6 0.4] [--weights 0.5]
        [--extend 0 4] [--streamed-poses] [--after-last]

SESSION is a processed simulated session (``mesh.ply``, ``merged.ply``, ``poses.json``, each view's cached
``maps.npz``). For each voxel (mm), marching-cubes weight threshold and rim extension (pixels), the views' depth maps are
integrated into a :class:`rangekit.surface.block_volume.BlockVolume` at their registered poses (and, with
``--streamed-poses``, at the poses the streaming worker gives them before any joint registration), and prints, one
line each:

- the steps' CPU seconds (integration a view, marching cubes, the observed rule's tree, the cut and refinement);
- the completeness against the simulator's truth of the marching-cubes surface itself (``full``), of its observed
  cut (``cut``) and of the cut refined onto the points (``refined``, the observed mesh), and the refined mesh's RMS;
- the true surface samples the views see that the refined mesh misses (beyond the evaluator's 1 mm), split by
  what explains them: ``no point`` (no input point within 1 mm: the decode never saw them), ``full misses`` (the
  volume's own surface is more than 1 mm off: the TSDF lost them), ``cut`` (the volume had them, the observed cut
  dropped them), each with its height above the table top and the most head-on view's incidence (against the
  nearest input point's normal). "Input points" are Poisson's sample of ``merged.ply``, as ``rangekit process``
  takes them (every k-th point, about 700k).

The session's own mesh.ply (``rangekit process``'s Poisson route) is measured the same way first, for reference.
``--after-last``: only the steps after the last view (:func:`after_last`), CPU and wall seconds each.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


def _cpu() -> float:
    return time.process_time()


def _sample(cloud, points: int):
    from rangekit.surface.cloud import PointCloud

    step = max(1, -(-len(cloud.points) // points))
    return PointCloud(cloud.points[::step].copy(), None, cloud.normals[::step].copy())


class Setup:
    """The session's views, poses, evaluator and Poisson's input sample (``rangekit process``'s), loaded once."""

    def __init__(self, folder: Path) -> None:
        from rangekit.app.process.register import evaluator_angles
        from rangekit.app.scan.truth import session_evaluator
        from rangekit.formats.clouds import load_cloud
        from rangekit.formats.sessions.session import load_session
        from rangekit.surface.fusion import poisson_input

        self.session = load_session(folder)
        self.camera = self.session.rig.camera
        self.poses = [np.array(v["T_world_view"]) for v in json.loads((folder / "poses.json").read_text())["views"]]
        self.depths = [np.load(folder / f"view_{k:03d}" / "maps.npz")["depth"] for k in range(len(self.poses))]
        self.evaluate = session_evaluator(self.session)
        self.angles = evaluator_angles(self.session.views, multi_pass=False)
        cloud = load_cloud(folder / "merged.ply")
        sample = _sample(cloud, 700_000)
        used = poisson_input(sample)
        self.points, self.normals = sample.points[used], sample.normals[used]
        self.folder = folder

    def accuracy(self, mesh):
        return self.evaluate(mesh, self.angles).accuracy

    def truth(self):
        """(samples in the session world (n, 3), seen (n,) bool): the evaluator's truth samples after a call."""
        from rangekit.geometry import apply_T

        t = self.evaluate._truth
        return apply_T(t.M0, t.samples), t.seen


def _misses(setup: Setup, full, refined) -> str:
    """The seen truth samples the refined mesh misses, split by cause (module doc)."""
    from scipy.spatial import cKDTree

    from rangekit.geometry import apply_T, compose, invert_T

    P, seen = setup.truth()
    tol = 1e-3
    miss = np.flatnonzero(seen & ~_near(refined, P, tol))
    if len(miss) == 0:
        return "misses none"
    Q = P[miss]
    no_point = cKDTree(setup.points).query(Q, distance_upper_bound=tol)[0] > tol
    full_miss = ~_near(full, Q, tol)
    rig = setup.session.rig
    h = apply_T(invert_T(rig.T_world_table), Q)[:, 2] if rig.T_world_table is not None else np.zeros(len(Q))
    # The most head-on view of each missed sample (the angle between the view ray and the truth's normal is not
    # known here: the angle to the nearest input point's normal instead).
    _, j = cKDTree(setup.points).query(Q)
    n = setup.normals[j]
    best = np.zeros(len(Q))
    for T in setup.poses:
        c = compose(T, setup.camera.T_world_cam)[:3, 3]
        ray = c - Q
        ray /= np.linalg.norm(ray, axis=1, keepdims=True)
        best = np.maximum(best, np.abs(np.sum(ray * n, axis=1)))
    inc = np.degrees(np.arccos(np.clip(best, 0, 1)))

    def part(mask, name):
        if not mask.any():
            return f"{name} 0"
        return (f"{name} {mask.sum()} (height {np.median(h[mask]) * 1e3:.1f} mm median, "
                f"{np.mean(h[mask] < 0.004) * 100:.0f}% under 4 mm; incidence {np.median(inc[mask]):.0f} deg median, "
                f"{np.mean(inc[mask] > 70) * 100:.0f}% over 70)")

    cut = ~no_point & ~full_miss
    return (f"misses {len(miss)} of {seen.sum()} seen: " + "; ".join([
        part(no_point, "no point"), part(~no_point & full_miss, "full misses"), part(cut, "cut")]))


def _near(mesh, P: np.ndarray, tol: float) -> np.ndarray:
    from rangekit.sim.truth.evaluate import _within

    return _within(mesh, P, tol)


def streamed(setup: Setup, voxel: float, weight: float, extend: int, poses: list, label: str) -> None:
    from rangekit.geometry import compose
    from rangekit.surface.block_volume import BlockVolume
    from rangekit.surface.mesh import mesh_from_open3d
    from rangekit.surface.observed import observed_rule
    from rangekit.surface.refine import REFINE_NEIGHBOURS, refine_to_points

    c0 = _cpu()
    volume = BlockVolume(voxel, extend_px=extend)
    for depth, T in zip(setup.depths, poses):
        volume.integrate(depth, setup.camera.with_pose(compose(T, setup.camera.T_world_cam)))
    c1 = _cpu()
    full = mesh_from_open3d(volume.mesh(weight))
    c2 = _cpu()
    rule = observed_rule(setup.points)
    c3 = _cpu()
    cut, d, idx = rule.observed_near(full, min(REFINE_NEIGHBOURS, rule.tree.n))
    c4 = _cpu()
    refined = refine_to_points(cut, rule.tree.data, setup.normals, tree=rule.tree, near=(d, idx))
    c5 = _cpu()
    projected = refine_to_points(cut, rule.tree.data, setup.normals, tree=rule.tree, near=(d, idx), sag=1.0)
    c6 = _cpu()
    a_full, a_cut, a, a_p = (setup.accuracy(m) for m in (full, cut, refined, projected))
    print(f"{label} poses, voxel {voxel * 1e3:.2f} mm, weight {weight:g}, extended {extend} px: integrate "
          f"{(c1 - c0) / len(setup.depths):.2f} CPU-s a view, marching cubes {c2 - c1:.2f}, observed rule's tree "
          f"{c3 - c2:.2f}, cut (its query) {c4 - c3:.2f}, refine {c5 - c4:.2f} (projection only {c6 - c5:.2f}); "
          f"completeness full {a_full.completeness * 100:.2f}% cut {a_cut.completeness * 100:.2f}% refined "
          f"{a.completeness * 100:.2f}% (projected only {a_p.completeness * 100:.2f}%); refined RMS "
          f"{a.rms * 1e3:.4f} mm p95 {a.p95 * 1e3:.4f} mm (projected only {a_p.rms * 1e3:.4f} / {a_p.p95 * 1e3:.4f}), "
          f"{len(refined.vertices):,} vertices", flush=True)
    print("  " + _misses(setup, full, refined), flush=True)


def after_last(setup: Setup, voxel: float, extend: int, workers: int) -> None:
    """The steps after the last view alone, as a scan would run them with every earlier view integrated ahead: the
    last view's integration, marching cubes, the observed rule's tree, the cut's query on ``workers`` threads (each
    query its own: the same answers), the cut, the vertices projected onto the points' planes (no halving), the
    mesh written; CPU (this process, every thread) and wall seconds of each."""
    import tempfile

    from rangekit.formats.meshes import save_mesh
    from rangekit.geometry import compose
    from rangekit.surface.block_volume import BlockVolume
    from rangekit.surface.mesh import TriangleMesh, mesh_from_open3d
    from rangekit.surface.observed import _kept, _near_enough, observed_rule
    from rangekit.surface.refine import REFINE_NEIGHBOURS, _project

    volume = BlockVolume(voxel, extend_px=extend)
    views = [(d, setup.camera.with_pose(compose(T, setup.camera.T_world_cam))) for d, T in zip(setup.depths, setup.poses)]
    for depth, camera in views[:-1]:
        volume.integrate(depth, camera)
    marks = [("start", _cpu(), time.perf_counter())]

    def mark(name):
        marks.append((name, _cpu(), time.perf_counter()))

    volume.integrate(*views[-1])
    mark("integrate the last view")
    full = mesh_from_open3d(volume.mesh())
    mark("marching cubes")
    rule = observed_rule(setup.points)
    mark("the rule's tree")
    V = full.vertices
    d, idx = rule.tree.query(V, k=REFINE_NEIGHBOURS, workers=workers)
    mark(f"the cut's query ({workers} workers)")
    flags = _near_enough(d[:, 0], idx[:, 0], rule.tree, rule.spacing, rule.factor, rule.median, rule.k)
    cut, used = _kept(full, flags)
    mark("the cut")
    placed, _ = _project(cut.vertices, rule.tree.data, setup.normals, REFINE_NEIGHBOURS, rule.tree,
                         (d[used], idx[used]))
    mesh = TriangleMesh(placed, cut.triangles)
    mark("the projection")
    with tempfile.TemporaryDirectory() as tmp:
        save_mesh(Path(tmp) / "mesh.ply", mesh)
    mark("mesh.ply written")
    steps = ", ".join(f"{b[0]} {b[1] - a[1]:.2f} / {b[2] - a[2]:.2f}" for a, b in zip(marks, marks[1:]))
    total = f"{marks[-1][1] - marks[0][1]:.2f} CPU-s / {marks[-1][2] - marks[0][2]:.2f} s"
    a = setup.accuracy(mesh)
    print(f"after the last view, voxel {voxel * 1e3:.2f} mm, extended {extend} px (CPU-s / wall s): {steps}; "
          f"total {total}; completeness {a.completeness * 100:.2f}%, RMS {a.rms * 1e3:.4f} mm, "
          f"{len(mesh.vertices):,} vertices", flush=True)


def streamed_poses(setup: Setup) -> list:
    """Each view's pose as the scan's streaming worker places it, views in order
    (:meth:`rangekit.app.scan.streaming.StreamingViews._place`)."""
    from rangekit.app.process.options import ProcessOptions
    from rangekit.app.scan.streaming import StreamingViews
    from rangekit.formats.clouds import load_cloud

    worker = StreamingViews(setup.folder, ProcessOptions())
    clouds = [load_cloud(setup.folder / f"view_{k:03d}" / "cloud.ply") for k in range(len(setup.poses))]
    return [worker._place(k, cloud, setup.session) for k, cloud in enumerate(clouds)], clouds


def points_at(clouds: list, poses: list) -> tuple[np.ndarray, np.ndarray]:
    """The views' points merged at ``poses`` and sampled as ``rangekit process`` samples Poisson's input: (points,
    normals)."""
    from rangekit.surface.cloud import merge_clouds
    from rangekit.surface.fusion import poisson_input

    sample = _sample(merge_clouds(clouds, np.array(poses)), 700_000)
    used = poisson_input(sample)
    return sample.points[used], sample.normals[used]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("session", type=Path)
    ap.add_argument("--voxels", type=float, nargs="+", default=[0.6, 0.4], help="voxel sides, mm")
    ap.add_argument("--weights", type=float, nargs="+", default=[0.5], help="marching cubes' weight thresholds")
    ap.add_argument("--extend", type=int, nargs="+", default=[0, 4], help="pixels each depth map is carried past "
                    "its rim (BlockVolume's extend_px)")
    ap.add_argument("--streamed-poses", action="store_true", help="also at the poses the scan's streaming worker "
                    "places the views at (the turntable prior refined by ICP against the nearest view placed before), "
                    "without the joint registration")
    ap.add_argument("--after-last", action="store_true", help="only the steps after the last view (the last "
                    "--voxels and --extend), the cut's query on 1 then 2 threads: CPU and wall seconds")
    args = ap.parse_args()
    from rangekit.formats.meshes import load_mesh

    setup = Setup(args.session)
    poisson = load_mesh(args.session / "mesh.ply")
    a = setup.accuracy(poisson)
    print(f"{args.session}: {len(setup.depths)} views, {len(setup.points):,} points; mesh.ply (Poisson): "
          f"completeness {a.completeness * 100:.2f}%, RMS {a.rms * 1e3:.4f} mm", flush=True)
    print("  " + _misses(setup, poisson, poisson), flush=True)
    poses = {"registered": (setup.poses, setup.points, setup.normals)}
    if args.streamed_poses:
        Ts, clouds = streamed_poses(setup)
        poses["streamed"] = (Ts, *points_at(clouds, Ts))
        step = [np.linalg.norm(a[:3, 3] - b[:3, 3]) for a, b in zip(setup.poses, Ts)]
        print(f"streamed poses against the registered: at most {max(step) * 1e3:.3f} mm apart (translation)")
    if args.after_last:
        for workers in (1, 2):
            after_last(setup, args.voxels[-1] * 1e-3, args.extend[-1], workers)
        return 0
    for label, (Ts, points, normals) in poses.items():
        setup.points, setup.normals = points, normals
        for voxel in args.voxels:
            for weight in args.weights:
                for extend in args.extend:
                    streamed(setup, voxel * 1e-3, weight, extend, Ts, label)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
