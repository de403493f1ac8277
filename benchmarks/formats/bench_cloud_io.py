"""PLY reading speed: rangekit's vectorised reader side by side with plyfile, the usual Python peer.

Inputs: the Stanford scan bun000.ply (ASCII, 40,256 vertices and a ragged 512 x 400 ``range_grid``;
from ../shared/data, skipped when absent) and a binary mesh of about 900k triangles written by
rangekit (an Open3D sphere). The reader's old test assert, now measured here: bun000 in under 1 s.

    .venv/bin/python benchmarks/formats/bench_cloud_io.py [--repeat 3] [--bunny PATH/bun000.ply] [--markdown]

``--markdown`` prints docs/benchmarks.md's table (a ``make docs-figures`` block).

Prints a table (median seconds, ratio plyfile / rangekit) and exits non-zero if bun000 takes 1 s or more.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]  # the repo (this is benchmarks/ROOM/SCRIPT.py)
sys.path[:0] = [str(ROOT / "benchmarks" / "harness"), str(ROOT / "tools")]  # _timing, tree_peak; docs_scan
from _timing import timed  # noqa: E402

def _bunny() -> Path:
    from rangekit.sim.scene.zoo import data_folders  # $RANGEKIT_DATA, ../shared/data of a checkout or a worktree
    paths = [folder / "stanford-bunny" / "bun000.ply" for folder in data_folders()]
    return next((p for p in paths if p.is_file()), paths[0])


TARGET_S = 1.0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=3, help="timed repetitions (median reported)")
    ap.add_argument("--bunny", type=Path, help="path of bun000.ply (default: in the shared data)")
    ap.add_argument("--markdown", action="store_true", help="print the table of docs/benchmarks.md")
    args = ap.parse_args()
    bunny = args.bunny or _bunny()

    import open3d as o3d
    import plyfile

    from rangekit.formats.clouds import load_cloud
    from rangekit.formats.meshes import load_mesh, save_mesh
    from rangekit.surface.mesh import TriangleMesh

    rows, ok = [], True
    if bunny.is_file():
        def peer_bunny():
            d = plyfile.PlyData.read(str(bunny))
            v = d["vertex"]
            return np.column_stack([v["x"], v["y"], v["z"]]), d["range_grid"]["vertex_indices"]

        t_ours, _ = timed(lambda: load_cloud(bunny), args.repeat, warmup=1)
        t_peer, _ = timed(peer_bunny, args.repeat, warmup=1)
        rows.append(("bun000.ply (ASCII, 40,256 vertices, ragged 512 x 400 `range_grid`), `load_cloud`"
                     if args.markdown else "bun000.ply (ASCII, range grid)", t_ours, t_peer))
        ok = t_ours < TARGET_S
    else:
        print(f"(skipped bun000.ply: not found at {bunny})")

    with tempfile.TemporaryDirectory() as tmp:
        s = o3d.geometry.TriangleMesh.create_sphere(radius=0.1, resolution=474)
        path = Path(tmp) / "sphere.ply"
        save_mesh(path, TriangleMesh(np.asarray(s.vertices), np.asarray(s.triangles)))
        n = len(s.triangles)

        def peer_mesh():
            d = plyfile.PlyData.read(str(path), known_list_len={"face": {"vertex_indices": 3}})
            return np.asarray(d["face"]["vertex_indices"]).astype(np.int64)

        t_ours, _ = timed(lambda: load_mesh(path), args.repeat, warmup=1)
        t_peer, _ = timed(peer_mesh, args.repeat, warmup=1)
        rows.append((f"{n:,}-triangle binary mesh, `load_mesh` (with TriangleMesh checks) vs plyfile with "
                     "`known_list_len` (memory-mapped)" if args.markdown else f"{n:,}-triangle mesh (binary)",
                     t_ours, t_peer))

    with tempfile.TemporaryDirectory() as tmp:  # a scan's merged.ply layout: normals, colours, sigma
        import io

        from rangekit.formats.clouds import save_cloud
        from rangekit.formats.ply_write import _vertex_records
        from rangekit.surface.cloud import PointCloud

        rng = np.random.default_rng(0)
        n = 2_000_000
        cloud = PointCloud(rng.normal(size=(n, 3)), rng.random((n, 3)), rng.normal(size=(n, 3)), rng.random(n))
        path = Path(tmp) / "merged.ply"

        def peer_write():
            rec = _vertex_records(cloud.points, cloud.normals, cloud.colours, cloud.sigma)
            buf = io.BytesIO()
            plyfile.PlyData([plyfile.PlyElement.describe(rec, "vertex")]).write(buf)
            (Path(tmp) / "peer.ply").write_bytes(buf.getvalue())

        def peer_read():
            v = plyfile.PlyData.read(str(path))["vertex"].data
            return np.column_stack([v["x"], v["y"], v["z"]]), np.column_stack([v["nx"], v["ny"], v["nz"]])

        t_ours, _ = timed(lambda: save_cloud(path, cloud), args.repeat, warmup=1)
        t_peer, _ = timed(peer_write, args.repeat, warmup=1)
        rows.append(("2M-point cloud with normals, colours and sigma (a scan's merged.ply), `save_cloud` (with "
                     "the atomic write's fsync and rename) vs plyfile's writer" if args.markdown
                     else "2M-point cloud, save_cloud (binary)", t_ours, t_peer))
        t_ours, _ = timed(lambda: load_cloud(path), args.repeat, warmup=1)
        t_peer, _ = timed(peer_read, args.repeat, warmup=1)
        rows.append(("the same cloud, `load_cloud` (plyfile's memory map, then rangekit's checks) vs plyfile "
                     "alone" if args.markdown else "2M-point cloud, load_cloud (binary)", t_ours, t_peer))

    if args.markdown:
        print("| input | rangekit | plyfile | plyfile / rangekit |\n|---|---|---|---|")
        for name, a, b in rows:
            print(f"| {name} | {a:.3f} s | {b:.3f} s | {b / a:.1f}x |")
        if not bunny.is_file():
            print(f"\n(bun000.ply not found at {bunny}: its row is missing.)")
        return 0
    print(f"{'input':38s} {'rangekit':>10s} {'plyfile':>10s} {'plyfile/rangekit':>17s}")
    for name, a, b in rows:
        print(f"{name:38s} {a:9.3f}s {b:9.3f}s {b / a:16.1f}x")
    if not ok:
        print(f"bun000.ply took {rows[0][1]:.3f} s, target < {TARGET_S} s")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
