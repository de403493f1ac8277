"""Registration of a simulated 12-view scan's clouds: rangekit vs Open3D's multiway recipe (for process's speed).

    PYTHONPATH=. .venv/bin/python -m rangekit scan --out /tmp/scan12 --no-report    # once, ~3 min
    PYTHONPATH=. .venv/bin/python benchmarks/registration/bench_registration_scan.py /tmp/scan12
    ... --ours-only --no-prior      # the view graph (docs/registration.md): no prior, against every pair
    ... --graph-only                # the view graph's per-view cost (e.g. 12 against 36 views)
    ... --skip-fpfh --markdown      # docs/benchmarks.md's table and ratio (a make docs-figures block)

The clouds are the session's ``view_*/cloud.ply`` (what ``rangekit process`` registers); the truth is the
simulator's turntable poses (the rig's ``T_world_table`` and the session's angles), which is also the
prior ``rangekit process`` gives. Every method runs in this one process on the same clouds and is
charged CPU seconds (user + sys of all its threads, ``resource.getrusage``), not wall time: the machine is
shared. Rotation errors are against the truth, over views 1..n-1 (view 0 is the frame).

1. rangekit ``register_views`` with the turntable prior (``turntable=True``, as ``rangekit process``), and with the
   settings before the speed work on rangekit process (all pairs, 50k joint samples) for the ratio.
2. Open3D's multiway-registration tutorial as written: all pairs, coarse ICP from the identity at 15
   voxels then fine at 1.5, odometry nodes, pose graph (Levenberg-Marquardt, prune 0.25).
3. The same with the turntable prior: nodes and every ICP start at the prior, coarse step at 4 voxels.
4. The same with FPFH + RANSAC (Open3D's global-registration tutorial) as every pair's coarse step.
"""

from __future__ import annotations

import argparse
import resource
import sys
from pathlib import Path

import numpy as np

from rangekit.formats.clouds import load_cloud
from rangekit.formats.sessions.session import Session
from rangekit.geometry import invert_T, rotation_angle
from rangekit.rig.rig_file import turntable_prior
from rangekit.surface.cloud import bbox_diagonal


def cpu_seconds() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def charged(fn):
    """(CPU seconds of ``fn()``, its result)."""
    c = cpu_seconds()
    out = fn()
    return cpu_seconds() - c, out


def rotation_errors(T_est: np.ndarray, T_true: np.ndarray) -> np.ndarray:
    """(n-1,) degrees, views 1.. (both sets of poses in view 0's frame)."""
    return np.array([np.degrees(rotation_angle(a[:3, :3] @ b[:3, :3].T)) for a, b in zip(T_est[1:], T_true[1:])])


def o3d_multiway(clouds, voxel: float, prior: np.ndarray | None = None, coarse: float = 15.0,
                 fpfh: bool = False) -> np.ndarray:
    """Open3D's multiway registration tutorial (pairwise ICP coarse then fine, pose graph, global
    optimisation). ``prior``: (n, 4, 4) start poses (else the identity and odometry, as the tutorial);
    ``coarse``: the coarse ICP distance in voxels (tutorial: 15); ``fpfh``: FPFH + RANSAC first (global
    registration tutorial). Returns (n, 4, 4) poses in view 0's frame."""
    import open3d as o3d

    reg = o3d.pipelines.registration
    pcds = []
    for c in clouds:
        pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(c.points)).voxel_down_sample(voxel)
        pc.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=voxel * 2, max_nn=30))
        pcds.append(pc)
    feats = [reg.compute_fpfh_feature(pc, o3d.geometry.KDTreeSearchParamHybrid(radius=voxel * 5, max_nn=100))
             for pc in pcds] if fpfh else None
    d_coarse, d_fine = voxel * coarse, voxel * 1.5
    n = len(pcds)
    graph = reg.PoseGraph()
    odometry = np.eye(4)
    graph.nodes.append(reg.PoseGraphNode(np.eye(4) if prior is None else prior[0]))
    for s in range(n):
        for t in range(s + 1, n):
            init = np.eye(4) if prior is None else invert_T(prior[t]) @ prior[s]   # source s into target t
            if fpfh:
                init = reg.registration_ransac_based_on_feature_matching(
                    pcds[s], pcds[t], feats[s], feats[t], True, d_fine,
                    reg.TransformationEstimationPointToPoint(False), 3,
                    [reg.CorrespondenceCheckerBasedOnEdgeLength(0.9), reg.CorrespondenceCheckerBasedOnDistance(d_fine)],
                    reg.RANSACConvergenceCriteria(100000, 0.999)).transformation
            else:
                init = reg.registration_icp(pcds[s], pcds[t], d_coarse, init,
                                            reg.TransformationEstimationPointToPlane()).transformation
            r = reg.registration_icp(pcds[s], pcds[t], d_fine, init, reg.TransformationEstimationPointToPlane())
            info = reg.get_information_matrix_from_point_clouds(pcds[s], pcds[t], d_fine, r.transformation)
            if t == s + 1:
                odometry = np.asarray(r.transformation) @ odometry
                graph.nodes.append(reg.PoseGraphNode(np.linalg.inv(odometry) if prior is None else prior[t]))
            graph.edges.append(reg.PoseGraphEdge(s, t, r.transformation, info, uncertain=t != s + 1))
    reg.global_optimization(graph, reg.GlobalOptimizationLevenbergMarquardt(), reg.GlobalOptimizationConvergenceCriteria(),
                            reg.GlobalOptimizationOption(max_correspondence_distance=d_fine, edge_prune_threshold=0.25,
                                                         reference_node=0))
    T = np.stack([np.asarray(nd.pose) for nd in graph.nodes])
    return np.einsum("ij,njk->nik", invert_T(T[0]), T)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("session", type=Path, help="a simulated session folder (rangekit scan --out ...)")
    ap.add_argument("--skip-fpfh", action="store_true", help="leave out the FPFH + RANSAC recipe (about 1 min)")
    ap.add_argument("--ours-only", action="store_true", help="leave out the Open3D recipes")
    ap.add_argument("--no-prior", action="store_true",
                    help="add rangekit with no prior: the view graph's coarse pairs (k=4 most similar) and all pairs")
    ap.add_argument("--graph-only", action="store_true",
                    help="only the default with the prior and the view graph with none (per-view cost at many views)")
    ap.add_argument("--markdown", action="store_true",
                    help="print docs/benchmarks.md's table (without the long-links row) and the CPU/error ratio")
    args = ap.parse_args()
    from rangekit.registration.multiview import MultiViewOptions, register_views
    from rangekit.registration.pairs import all_pairs, nearest_and_long_links

    session = Session.load(args.session)
    views = session.done_views
    clouds = [load_cloud(v.folder / "cloud.ply") for v in views]
    truth = turntable_prior(session.rig.T_world_table, [v.angle for v in views])
    voxel = bbox_diagonal(clouds) / 110.0   # rangekit's coarse voxel
    joint_lines: dict[str, str] = {}

    def ours(name: str, options, prior: bool = True):
        def say(msg: str) -> None:
            if msg.startswith(("joint refinement", "view graph")):
                joint_lines[name] = joint_lines.get(name, "") + msg + "; "
        return name, lambda: register_views(clouds, init_T_world_view=truth if prior else None, options=options,
                                            progress=say).T_world_view

    cases = [
        ours("rangekit `register_views`, turntable prior (as `rangekit process`)", MultiViewOptions(turntable=True)),
        ours("rangekit, the same with the joint refinement stopped at 0.1 um (before issue 20's last stop)",
             MultiViewOptions(turntable=True, joint_tolerance=1e-7)),
        ours("rangekit, turntable prior, k=4 nearest + 4 long links (not the default: issue 21)",
             MultiViewOptions(turntable=True, pairs=nearest_and_long_links(4))),
        ours("rangekit before issue 20 (all pairs, 50k joint samples, joint stop 0.1 um)",
             MultiViewOptions(pairs=all_pairs, joint_samples=50000, joint_tolerance=1e-7)),
    ]
    if args.markdown:
        cases = [c for c in cases if "long links" not in c[0]]
    if args.graph_only:
        cases = cases[:1] + [ours("rangekit, no prior: view graph (coarse k=4 most similar, k=4 nearest + 4 long links)",
                                  MultiViewOptions(), prior=False)]
    elif args.no_prior:
        cases += [ours("rangekit, no prior: view graph (coarse k=4 most similar, k=4 nearest + 4 long links)",
                       MultiViewOptions(), prior=False),
                  ours("rangekit, no prior: every pair (before issue 21)",
                       MultiViewOptions(coarse_neighbours=None, pairs=all_pairs), prior=False)]
    if not args.ours_only and not args.graph_only:
        cases += [("Open3D multiway, as the tutorial writes it", lambda: o3d_multiway(clouds, voxel)),
                  ("Open3D multiway, turntable prior, coarse ICP at 4 voxels",
                   lambda: o3d_multiway(clouds, voxel, truth, 4.0))]
    if not args.skip_fpfh and not args.ours_only and not args.graph_only:
        cases.append(("Open3D multiway, FPFH + RANSAC coarse step", lambda: o3d_multiway(clouds, voxel, fpfh=True)))
    head = f"{len(clouds)} clouds, {sum(len(c) for c in clouds):,} points; Open3D voxel {voxel * 1e3:.2f} mm\n"
    print(head, file=sys.stderr if args.markdown else sys.stdout)
    print("| method | CPU s | mean rotation error | max |")
    print("|---|---|---|---|")
    results = {}
    for name, fn in cases:
        secs, T = charged(fn)
        e = rotation_errors(T, truth)
        results[name] = (secs, e.mean())
        per_view = "" if args.markdown else f" ({secs / len(clouds):.3f} per view)"
        print(f"| {name} | {secs:.2f}{per_view} | {e.mean():.4f} deg | {e.max():.4f} deg |", flush=True)
    print()
    if args.markdown:
        ours_s, ours_e = results[cases[0][0]]
        o3d_s, o3d_e = results.get("Open3D multiway, turntable prior, coarse ICP at 4 voxels", (float("nan"),) * 2)
        print(f"rangekit: **{ours_s / o3d_s:.2f}x** the CPU of Open3D's recipe with the prior (target <= 1x: "
              f"{'met' if ours_s <= o3d_s else 'not met'} in this run), at 1/{o3d_e / ours_e:.0f} of its mean "
              f"rotation error ({ours_e:.4f} deg; target <= 0.01 deg).")
        for name, line in joint_lines.items():
            print(f"{name}: {line}", file=sys.stderr)
        return 0
    for name, line in joint_lines.items():
        print(f"{name}: {line}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
