"""Quality map on real scans with no truth (docs/metrology.md's quality map): the Stanford bunny's range scans,
registered, against the Stanford reconstruction ``bun_zipper.ply``; per mesh vertex the disagreement of the views that
see it (:func:`rangekit.surface.quality.view_disagreement`).

    PYTHONPATH=. python benchmarks/surface/bench_quality_map.py [--data ../shared/data] [--poses rangekit|conf]
                                                                [--radius-mm 1.0]

``--poses conf`` places the scans by Stanford's ``bun.conf``; ``rangekit`` (default) registers them with
:func:`rangekit.registration.multiview.register_views` starting from bun.conf (the pipeline's poses).
Prints the share of vertices seen by 2+ views and the RMS, median, 95th percentile and largest
disagreement, overall and per number of views.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from rangekit.formats.clouds import load_cloud
from rangekit.formats.meshes import load_mesh
from rangekit.formats.stanford_conf import load_stanford_conf
from rangekit.geometry import apply_T
from rangekit.registration.multiview import register_views
from rangekit.surface.quality import vertex_normals, view_disagreement

ROOT = Path(__file__).resolve().parents[2]  # the repo (this is benchmarks/ROOM/SCRIPT.py)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--data", type=Path, default=ROOT.parent / "shared" / "data")
    ap.add_argument("--poses", choices=["rangekit", "conf"], default="rangekit")
    ap.add_argument("--radius-mm", type=float, default=1.0)
    args = ap.parse_args()
    folder = args.data / "stanford-bunny"
    names, T = load_stanford_conf(folder / "bun.conf")
    clouds = [load_cloud(folder / n) for n in names]
    t0 = time.perf_counter()
    if args.poses == "rangekit":
        T = register_views(clouds, init_T_world_view=T).T_world_view
    mesh = load_mesh(folder / "bun_zipper.ply")
    n = vertex_normals(mesh.vertices, mesh.triangles)
    q = view_disagreement(mesh.vertices, n, [apply_T(Tk, c.points) for c, Tk in zip(clouds, T)],
                          radius=args.radius_mm * 1e-3)
    d = q.disagreement[np.isfinite(q.disagreement)]
    print(f"{len(names)} scans ({', '.join(names)}), poses {args.poses}, mesh {len(mesh.vertices)} vertices, "
          f"radius {args.radius_mm:g} mm ({time.perf_counter() - t0:.1f} s)")
    print(f"seen by >= 2 views: {d.size / len(mesh.vertices):.1%}; disagreement RMS {np.sqrt(np.mean(d ** 2)) * 1e3:.4f} mm, "
          f"median {np.median(d) * 1e3:.4f} mm, p95 {np.percentile(d, 95) * 1e3:.4f} mm, max {d.max() * 1e3:.4f} mm")
    for k in range(2, int(q.n_views.max()) + 1):
        m = (q.n_views == k) & np.isfinite(q.disagreement)
        if m.any():
            dk = q.disagreement[m]
            print(f"  {k} views: {m.sum():6d} vertices, RMS {np.sqrt(np.mean(dk ** 2)) * 1e3:.4f} mm, "
                  f"p95 {np.percentile(dk, 95) * 1e3:.4f} mm")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
