"""``rangekit register`` and ``rangekit mesh``: scans into one frame, a cloud into a watertight mesh."""

from __future__ import annotations

import argparse
import time

import numpy as np

from rangekit.formats.output_sets import claim_folder
from rangekit.cli._common import check_output, int_in, note, positive_float, result, say
from rangekit.formats.sessions.files import MERGED_FILE, MESH_FILE, POSES_FILE


def cmd_register(args: argparse.Namespace) -> int:
    """rangekit register SCAN... [--init none|poses.json|FILE.conf|turntable:AXIS:STEP] --out DIR"""
    from rangekit.app.commands.register import register
    from rangekit.geometry import rotation_angle

    t0 = time.perf_counter()
    check_output(args.out, folder=True)
    replace = claim_folder(args.out, "registration", force=args.force,
                           inputs=list(args.scans) + [args.init],
                           names=(POSES_FILE, MERGED_FILE) + (() if args.no_mesh else (MESH_FILE,)))
    voxel = args.voxel_mm * 1e-3 if args.voxel_mm else None
    rep = register(args.scans, args.out, init=args.init, voxel=voxel, mesh=not args.no_mesh, progress=say,
                         neighbours=args.neighbours)
    res = rep.result
    say("edges (view i - view j): ICP inlier RMSE, overlap, accepted, synchronisation residual")
    for e in res.edges:
        say(f"  {e.i:2d}-{e.j:<2d} rmse {e.rmse * 1e3:7.3f} mm  overlap {e.overlap:5.2f}  "
            f"{'ok ' if e.accepted else 'rejected'}  {e.reason}")
    n_accepted = sum(e.accepted for e in res.edges)
    held = [e for e in res.edges if e.accepted and e.unconstrained]
    if held:
        say(f"warning: {len(held)} accepted edges are ambiguous (their overlap leaves a motion free); the prior "
            f"--init {args.init} was kept along it and is not checked by the data (see 'prior_kept' in {POSES_FILE})")
    rot = np.degrees(np.asarray(res.sync.edge_rotation_error))
    tr = np.asarray(res.sync.edge_translation_error) * 1e3
    say(f"synchronisation over {n_accepted} accepted edges: rotation residual mean {np.mean(rot):.4f} deg, "
        f"max {np.max(rot):.4f} deg; translation residual mean {np.mean(tr):.4f} mm, max {np.max(tr):.4f} mm")
    for k, T in enumerate(res.T_world_view):
        say(f"  view {k}: {rep.sources[k]}: rotation {np.degrees(rotation_angle(T[:3, :3])):8.3f} deg, "
            f"translation {np.linalg.norm(T[:3, 3]) * 1e3:8.2f} mm")
    removed = replace()
    result(f"wrote {args.out}/{POSES_FILE}, {MERGED_FILE}{', ' + MESH_FILE if rep.mesh_path else ''} in "
        f"{time.perf_counter() - t0:.1f} s" + (f"; removed the earlier {', '.join(removed)}" if removed else ""))
    return 0


def cmd_mesh(args: argparse.Namespace) -> int:
    """rangekit mesh CLOUD --out MESH"""
    from rangekit.errors import MeshError, naming
    from rangekit.formats.clouds import load_cloud
    from rangekit.formats.meshes import MESH_FORMATS, save_mesh
    from rangekit.surface.cloud import oriented_normals_cloud
    from rangekit.surface.fusion import poisson_input_problem, poisson_mesh

    t0 = time.perf_counter()
    check_output(args.out, suffixes=MESH_FORMATS, what="mesh", force=args.force, inputs=[args.cloud])
    cloud = load_cloud(args.cloud)
    problem = poisson_input_problem(cloud.points)
    if problem:  # before estimating normals, which needs less
        raise MeshError(f"{args.cloud}: cannot build a closed surface: {problem}")
    with naming(args.cloud):
        if cloud.normals is None:
            note(f"read {len(cloud)} points without normals: estimating outward normals")
            cloud = oriented_normals_cloud(cloud.points)
        note(f"{len(cloud)} points; screened Poisson, depth {args.depth}")
        mesh = poisson_mesh(cloud, depth=args.depth)
    save_mesh(args.out, mesh)
    result(f"wrote {args.out}: {len(mesh.vertices)} vertices, {len(mesh.triangles)} triangles, watertight "
        f"{mesh.is_watertight}, in {time.perf_counter() - t0:.1f} s")
    return 0


def add_parsers(sub) -> None:
    reg = sub.add_parser("register", help="register scans into one frame, merge and mesh them",
                         description="Register point clouds (PLY incl. Stanford range grids, PCD, XYZ, NPY) into "
                                     f"the first scan's frame; writes DIR/{POSES_FILE}, DIR/{MERGED_FILE}, DIR/{MESH_FILE}.")
    reg.add_argument("scans", nargs="+", metavar="SCAN", help="scan files")
    reg.add_argument("--init", default="none",
                     help=f"prior poses: none (coarse alignment, see --neighbours), a {POSES_FILE}, a Stanford .conf, or "
                          "turntable:AX,AY,AZ:STEP_DEG[:PX,PY,PZ] (view i turned i*STEP degrees about the axis)")
    reg.add_argument("--voxel-mm", type=positive_float, default=None,
                     help="voxel for features and the first ICP round, mm (default: scene diagonal / 80)")
    reg.add_argument("--neighbours", type=int_in(0, 1000), default=None, metavar="K",
                     help="view graph: each view paired with its K nearest in rotation (+ 4 long links) and, "
                          "with no prior, coarse-aligned with its K most similar (widened until connected); "
                          "0 tries every pair (default: 4 with --init none, every pair with a prior)")
    reg.add_argument("--no-mesh", action="store_true", help="skip meshing")
    reg.add_argument("--out", required=True, help="output folder")
    reg.add_argument("--force", action="store_true", help="write over files in --out this run did not make: another command's set (a session, a capture, results), files of yours, an input")
    reg.set_defaults(func=cmd_register)

    mesh = sub.add_parser("mesh", help="fuse one cloud into a watertight mesh (screened Poisson)",
                          description="Screened Poisson reconstruction with low-density trimming and hole closing.")
    mesh.add_argument("cloud", metavar="CLOUD", help="point cloud file (normals are estimated if missing)")
    mesh.add_argument("--depth", type=int_in(4, 12), default=9, help="octree depth (default 9)")
    mesh.add_argument("--out", required=True, help="output mesh (.ply, .obj, .stl or .glb; checked before any work)")
    mesh.add_argument("--force", action="store_true", help="overwrite --out if it exists")
    mesh.set_defaults(func=cmd_mesh)
