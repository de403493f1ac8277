"""How far a processed session's closed mesh lies inside the space its views saw as empty (issue 51: no closed-mesh
vertex more than one voxel inside carved space), and how many of its vertices are flagged carved and unobserved.

    PYTHONPATH=. python benchmarks/surface/closed_inside_carved.py SESSION [SESSION ...]

The carved space is made again from each view's cache and poses.json as ``rangekit process`` makes it
(:func:`rangekit.app.process.carved.carved_space_of`). Not a timing.
"""

from __future__ import annotations

import sys
from pathlib import Path


def main(folders: list[str]) -> int:
    from rangekit.app.process.carved import carved_space_of
    from rangekit.formats.meshes import load_mesh

    for folder in map(Path, folders):
        space = carved_space_of(folder, load_mesh(folder / "mesh.ply"))
        closed = load_mesh(folder / "mesh_watertight.ply")
        d = space.depth_inside(closed.vertices)
        print(f"{folder}: most inside carved space {d.max() * 1e3:.3f} mm = {d.max() / space.voxel:.2f} voxel "
              f"({space.voxel * 1e3:.3f} mm); {int(closed.carved.sum())} carved, {int((~closed.observed).sum())} "
              f"unobserved of {len(closed.vertices)} vertices")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
