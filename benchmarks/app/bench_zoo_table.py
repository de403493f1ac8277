"""The object zoo table of docs/metrology.md from finished simulated scans (the zoo of hard objects).

    for obj in lumpy bunny shiny dark thin bowl steps; do rangekit scan --object $obj --out zoo_$obj --no-report; done
    PYTHONPATH=. .venv/bin/python benchmarks/app/bench_zoo_table.py zoo_lumpy zoo_bunny ...   # about 10 s per scan

Per scan folder (its ``session.json`` names the simulated object): the observed mesh's accuracy from
``summary.json`` (RMS, 95th percentile, completeness of the visible surface), the farthest vertex of
``mesh.ply`` from the true surface (every vertex, in the session world = the first view's frame, where the
object stands at turntable angle 0), the closed mesh's RMS, the views' cloud RMS range and the worst
view's pose against the true turntable pose (rotation, displacement of the object's centre).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from rangekit.formats.meshes import load_mesh
from rangekit.formats.sessions.session import Session
from rangekit.sim import default_scene
from rangekit.surface.mesh import TriangleMesh, distance_to_surface


def row(folder: Path) -> str:
    name = Session.load(folder).simulator.object
    summary = json.loads((folder / "summary.json").read_text())
    a, views = summary["accuracy"], summary["view_errors"]
    obj = default_scene(name).objects[0]
    d = distance_to_surface(load_mesh(folder / "mesh.ply").vertices, TriangleMesh(obj.world_vertices(), obj.triangles))
    cloud = [v["cloud"]["rms_mm"] for v in views]
    rot = max(v["registration"]["rotation_deg"] for v in views)
    move = max(v["registration"]["translation_mm"] for v in views)
    return (f"| {name} | {a['rms'] * 1e3:.3f} mm ({a['rms'] / a['diagonal']:.3%}) | {a['p95'] * 1e3:.3f} mm | "
            f"{a['completeness']:.1%} | {d.max() * 1e3:.2f} mm | {a['watertight']['rms'] * 1e3:.3f} mm | "
            f"{min(cloud):.3f}-{max(cloud):.3f} mm | {rot:.4f} deg, {move:.4f} mm |")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("folders", type=Path, nargs="+", help="finished simulated scan folders")
    args = ap.parse_args()
    print("| object | observed mesh RMS | p95 | completeness | farthest vertex | closed mesh RMS | per-view cloud RMS "
          "| poses (worst) |")
    print("|---|---|---|---|---|---|---|---|")
    for folder in args.folders:
        print(row(folder), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
