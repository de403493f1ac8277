"""Registration benchmarks, side by side with Open3D on the same data (the registration section of docs/benchmarks.md).

    .venv/bin/python benchmarks/registration/bench_registration.py [--skip-bunny] [--markdown]

Prints a markdown table; ``--markdown`` (docs/benchmarks.md's ``make docs-figures`` block) also states
whether the bunny's target (<= 90 s) was met.

1. Pairwise point-to-plane ICP, 100k <-> 100k points, 5 deg and 2% of the diagonal offset, KD-tree
   build included: rangekit vs ``open3d.pipelines.registration.registration_icp``.
2. Organised scans (two simulated views): projective association vs Open3D's KD-tree ICP.
3. 12-view turntable scan of the lumpy object (noise 0.05% of the diagonal), prior off by up to 3 deg
   and 2% of the diagonal: rangekit multi-view vs Open3D multiway registration (pose graph).
4. The same pairwise edges with 15% replaced by wrong relative poses (>= 30 deg off): robust vs plain
   spectral synchronisation.
5. Stanford bunny (10 scans, ``rangekit.sim.scene.zoo.data_folders``: $RANGEKIT_DATA or ../shared/data): --init none, time and agreement with bun.conf.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from rangekit.geometry import apply_T, axis_angle_to_R, invert_T, make_T, rotation_angle
from rangekit.metrology.pose_errors import pose_errors
from rangekit.surface.cloud import PointCloud
from rangekit.registration.icp import IcpOptions, OrganisedScan, icp

ROOT = Path(__file__).resolve().parents[2]  # the repo (this is benchmarks/ROOM/SCRIPT.py)
sys.path[:0] = [str(ROOT / "benchmarks" / "harness"), str(ROOT / "tools")]  # _timing, tree_peak; docs_scan
from _timing import timed  # noqa: E402



def bunny_folder() -> Path:
    """stanford-bunny/ in the first of rangekit.sim.scene.zoo's data folders ($RANGEKIT_DATA, ../shared/data beside
    the checkout or beside the folder holding it) that has it."""
    from rangekit.sim.scene.zoo import data_folders

    folders = [f / "stanford-bunny" for f in data_folders()]
    return next((f for f in folders if (f / "bun.conf").is_file()), folders[0])


def o3d_cloud(c: PointCloud):
    import open3d as o3d

    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(c.points))
    if c.normals is not None:
        pc.normals = o3d.utility.Vector3dVector(c.normals)
    return pc



def bench_pairwise() -> list[str]:
    import open3d as o3d
    import trimesh

    from rangekit.sim.scene.objects import lumpy

    tm = lumpy().to_trimesh()
    a, fa = trimesh.sample.sample_surface(tm, 100000, seed=1)
    b, fb = trimesh.sample.sample_surface(tm, 100000, seed=2)
    diag = float(np.linalg.norm(np.ptp(a, axis=0)))
    d = np.array([1.0, 0.5, -0.3])
    T = make_T(axis_angle_to_R([0.3, 1, 0.2], np.radians(5)), 0.02 * diag * d / np.linalg.norm(d))
    src = PointCloud(apply_T(invert_T(T), b), normals=tm.face_normals[fb] @ T[:3, :3])
    tgt = PointCloud(a, normals=tm.face_normals[fa])
    t_rk, r = timed(lambda: icp(src, tgt, options=IcpOptions(max_distance=0.01)))
    e_rk = np.degrees(rotation_angle(r.T_target_source[:3, :3] @ T[:3, :3].T))
    reg = o3d.pipelines.registration
    s3, t3 = o3d_cloud(src), o3d_cloud(tgt)
    t_o3, r3 = timed(lambda: reg.registration_icp(s3, t3, 0.01, np.eye(4), reg.TransformationEstimationPointToPlane(),
                                                  reg.ICPConvergenceCriteria(max_iteration=30)))
    e_o3 = np.degrees(rotation_angle(np.asarray(r3.transformation)[:3, :3] @ T[:3, :3].T))
    return [f"| pairwise point-to-plane ICP, 100k-100k, 5 deg + 2% (tree build included) | {t_rk:.3f} s, "
            f"{e_rk:.1e} deg | {t_o3:.3f} s, {e_o3:.1e} deg | {t_o3 / t_rk:.2f}x |"]


def bench_projective(scans) -> list[str]:
    import open3d as o3d

    reg = o3d.pipelines.registration
    cam = scans.rig.camera
    T_true = invert_T(scans.T_world_view[0]) @ scans.T_world_view[1]
    init = make_T(axis_angle_to_R([0, 0.2, 1], np.radians(2)), [0.002, 0, 0]) @ T_true
    target = OrganisedScan(scans.range_maps[0], scans.normal_maps[0], cam)
    opt = IcpOptions(max_distance=0.005, max_iterations=30, tolerance=1e-7)
    t_rk, r = timed(lambda: icp(scans.clouds[1], None, init_T_target_source=init, target_scan=target, options=opt))
    e_rk = np.degrees(rotation_angle(r.T_target_source[:3, :3] @ T_true[:3, :3].T))
    s3, t3 = o3d_cloud(scans.clouds[1]), o3d_cloud(scans.clouds[0])
    t_o3, r3 = timed(lambda: reg.registration_icp(s3, t3, 0.005, init, reg.TransformationEstimationPointToPlane(),
                                                  reg.ICPConvergenceCriteria(max_iteration=30)))
    e_o3 = np.degrees(rotation_angle(np.asarray(r3.transformation)[:3, :3] @ T_true[:3, :3].T))
    n = len(scans.clouds[1])
    return [f"| organised scans ({n // 1000}k points), projective association vs Open3D KD-tree | {t_rk:.3f} s, "
            f"{e_rk:.1e} deg | {t_o3:.3f} s, {e_o3:.1e} deg | {t_o3 / t_rk:.2f}x |"]


def o3d_multiway(clouds, init, voxel):
    """Open3D's multiway registration tutorial recipe: pairwise ICP, pose graph, global optimisation."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    pcs = [o3d_cloud(c).voxel_down_sample(voxel) for c in clouds]
    for pc in pcs:
        if not pc.has_normals():
            pc.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=voxel * 2, max_nn=30))
    n = len(pcs)
    graph = reg.PoseGraph()
    for k in range(n):
        graph.nodes.append(reg.PoseGraphNode(init[k]))  # node pose: view -> world
    fine = voxel * 1.5
    for i in range(n):
        for j in range(i + 1, n):
            T_i_j = invert_T(init[i]) @ init[j]
            r = reg.registration_icp(pcs[j], pcs[i], fine, T_i_j, reg.TransformationEstimationPointToPlane())
            if r.fitness < 0.2:
                continue
            info = reg.get_information_matrix_from_point_clouds(pcs[j], pcs[i], fine, r.transformation)
            graph.edges.append(reg.PoseGraphEdge(j, i, r.transformation, info, uncertain=abs(i - j) not in (1, n - 1)))
    reg.global_optimization(graph, reg.GlobalOptimizationLevenbergMarquardt(),
                            reg.GlobalOptimizationConvergenceCriteria(),
                            reg.GlobalOptimizationOption(max_correspondence_distance=fine, edge_prune_threshold=0.25,
                                                         reference_node=0))
    T = np.stack([np.asarray(nd.pose) for nd in graph.nodes])
    return np.einsum("ij,njk->nik", invert_T(T[0]), T)


def bench_multiview(scans) -> list[str]:
    from rangekit.registration.multiview import register_views
    from rangekit.registration.sync import synchronise
    from rangekit.sim.writers.scans import perturb_poses

    diag = scans.diag
    prior = perturb_poses(scans.T_world_view, max_angle=np.radians(3), max_translation=0.02 * diag, rng=1)
    t_rk, res = timed(lambda: register_views(scans.clouds, init_T_world_view=prior), repeat=1)
    rot, tr = pose_errors(res.T_world_view, scans.T_world_view)
    t_o3, T_o3 = timed(lambda: o3d_multiway(scans.clouds, prior, diag / 240), repeat=1)
    rot3, tr3 = pose_errors(T_o3, scans.T_world_view)
    lines = [f"| 12-view turntable, prior off 3 deg / 2% | {t_rk:.1f} s; rotation {rot[1:].mean():.4f} deg, "
             f"translation {tr[1:].mean() / diag:.1e} diag | {t_o3:.1f} s; {rot3[1:].mean():.4f} deg, "
             f"{tr3[1:].mean() / diag:.1e} diag | |"]
    # Robustness: replace 15% of the accepted edges by wrong relative poses (>= 30 deg off).
    rng = np.random.default_rng(5)
    edges = [(e.i, e.j, e.T_i_j) for e in res.edges if e.accepted]
    bad = rng.choice(len(edges), max(1, int(round(0.15 * len(edges)))), replace=False)
    corrupted = []
    for k, (i, j, T) in enumerate(edges):
        if k in bad:
            wrong = make_T(axis_angle_to_R(rng.normal(size=3), np.radians(rng.uniform(30, 120))),
                           rng.normal(size=3) * 0.05 * diag)
            T = wrong @ T
        corrupted.append((i, j, T))
    out = []
    for robust in (True, False):
        s = synchronise(len(scans.clouds), corrupted, robust=robust)
        r_, t_ = pose_errors(s.T_world_view, scans.T_world_view)
        out.append((r_[1:].mean(), t_[1:].mean() / diag))
    lines.append(f"| same edges, {len(bad)}/{len(edges)} replaced by wrong poses (>= 30 deg), synchronisation only | robust: "
                 f"{out[0][0]:.4f} deg, {out[0][1]:.1e} diag | plain spectral: {out[1][0]:.3f} deg, "
                 f"{out[1][1]:.1e} diag | |")
    return lines


BUNNY_TARGET_S = 90.0


def bench_bunny(verdict: bool = False) -> list[str]:
    from rangekit.formats.clouds import load_cloud
    from rangekit.formats.stanford_conf import load_stanford_conf
    from rangekit.registration.multiview import register_views

    DATA = bunny_folder()
    if not DATA.is_dir():
        return [f"| Stanford bunny | skipped: {DATA} absent (set RANGEKIT_DATA) | | |"]
    names, poses = load_stanford_conf(DATA / "bun.conf")
    clouds = [load_cloud(DATA / n) for n in names]
    t, res = timed(lambda: register_views(clouds), repeat=1)
    rot, tr = pose_errors(res.T_world_view, poses)
    target = f"target <= {BUNNY_TARGET_S:.0f} s: {'met' if t <= BUNNY_TARGET_S else 'not met'}" if verdict else ""
    return [f"| Stanford bunny, 10 scans, --init none | {t:.1f} s; vs bun.conf mean {rot.mean():.3f} deg / "
            f"{tr.mean() * 1e3:.3f} mm, max {rot.max():.3f} deg / {tr.max() * 1e3:.3f} mm | | {target} |"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--skip-bunny", action="store_true")
    ap.add_argument("--markdown", action="store_true", help="docs/benchmarks.md's block: the bunny's target too")
    args = ap.parse_args()
    from rangekit.sim.writers.scans import turntable_scans

    print("| case | rangekit | Open3D / baseline | speed ratio |")
    print("|---|---|---|---|")
    for line in bench_pairwise():
        print(line, flush=True)
    scans = turntable_scans(n_views=12, noise=0.0005, rng=0)
    for line in bench_projective(scans) + bench_multiview(scans):
        print(line, flush=True)
    if not args.skip_bunny:
        for line in bench_bunny(args.markdown):
            print(line, flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
