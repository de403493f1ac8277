"""Where a simulated session's closed mesh (mesh_watertight.ply) departs from the truth where no view can see.

The simulator's truth measures the closed mesh as ``rangekit process`` does (``unobserved_rms``: the mesh samples
whose nearest true point no view can see); this splits those samples by the nearest true point's height above
the table top, its true normal's z (table frame: -1 faces the table) and the mesh's own flags (observed, carved,
guessed), each row's share of the samples and of the squared error, its RMS and which side of the true surface
the mesh lies (``out``: outside the object). With ``--hull``, what bounds it: the carved space made again from
the views' cached maps and the registered poses as ``rangekit process`` makes it
(:func:`rangekit.app.process.carved.carved_space_of`), and the true surface's unseen
samples' distance to its hull (a closed mesh on the hull is that far off, whatever fills it), by height over the
table. Not a timing (issue 51 Deliver 4, docs/benchmarks.md).

    PYTHONPATH=. .venv/bin/python benchmarks/surface/closed_breakdown.py [--hull] SESSION [SESSION ...]
"""

from __future__ import annotations

import argparse

import numpy as np


def hull_bound(folder) -> list[str]:
    """The true surface's unseen samples' distance to the hull (RMS, by height over the table)."""
    from pathlib import Path

    from rangekit.app.process.carved import carved_space_of
    from rangekit.app.scan.truth import session_evaluator
    from rangekit.formats.meshes import load_mesh
    from rangekit.formats.sessions.session import Session
    from rangekit.geometry import apply_T, invert_T

    session = Session.load(Path(folder))
    evaluate = session_evaluator(session)
    evaluate.prepare([v.angle for v in session.done_views])
    truth = evaluate._truth
    space = carved_space_of(session, load_mesh(Path(folder) / "mesh.ply"))
    P = truth.samples[~truth.seen]
    d = space.depth_inside(P)
    z = apply_T(invert_T(session.rig.T_world_table), P)[:, 2]
    lines = [f"{folder}: the true unseen surface to the hull: RMS {np.sqrt(np.mean(d ** 2)) * 1e3:.2f} mm, "
             f"{np.mean(d < -space.voxel):.0%} more than a voxel ({space.voxel * 1e3:.2f} mm) inside it"]
    for lo, hi in ((0, 0.002), (0.002, 0.01), (0.01, np.inf)):
        sel = (z >= lo) & (z < hi)
        if sel.any():
            lines.append(f"  {lo * 1e3:.0f}-{hi * 1e3:.0f} mm over the table: {sel.mean():.0%} of it, "
                         f"RMS {np.sqrt(np.mean(d[sel] ** 2)) * 1e3:.2f} mm")
    return lines


def breakdown(folder) -> list[str]:
    from pathlib import Path

    from rangekit.app.scan.truth import session_evaluator
    from rangekit.formats.meshes import load_mesh
    from rangekit.formats.sessions.session import Session
    from rangekit.geometry import apply_T, invert_T
    from rangekit.sim.truth.evaluate import _closest_on, sample_surface

    session = Session.load(Path(folder))
    evaluate = session_evaluator(session)
    evaluate.prepare([v.angle for v in session.done_views])
    truth = evaluate._truth
    if not np.array_equal(truth.M0, np.eye(4)):
        raise SystemExit(f"{folder}: the first view is not at table angle 0")
    T_table_world = invert_T(session.rig.T_world_table)
    mesh = load_mesh(Path(folder) / "mesh_watertight.ply")
    P, face = sample_surface(mesh.vertices, mesh.triangles, 200_000, np.random.default_rng(0))
    d, Q, q_face = _closest_on(truth.truth, P)
    unseen = ~truth.observed(Q, q_face)
    t = truth.truth
    n = np.cross(t.vertices[t.triangles[:, 1]] - t.vertices[t.triangles[:, 0]],
                 t.vertices[t.triangles[:, 2]] - t.vertices[t.triangles[:, 0]])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    height = apply_T(T_table_world, Q)[:, 2]
    nz = (n @ T_table_world[:3, :3].T)[q_face, 2]
    outside = np.einsum("ij,ij->i", P - Q, n[q_face]) > 0
    corners = mesh.triangles[face]
    total = np.sum(d[unseen] ** 2)
    lines = [f"{folder}: unseen {unseen.mean():.1%} of the closed mesh, RMS {np.sqrt(np.mean(d[unseen] ** 2)) * 1e3:.2f} mm; "
             f"seen RMS {np.sqrt(np.mean(d[~unseen] ** 2)) * 1e3:.3f} mm",
             "| part (nearest true point) | share of unseen | RMS mm | share of squared error | outside |",
             "|---|---|---|---|---|"]

    def row(label, sel):
        sel = sel & unseen
        if sel.any():
            lines.append(f"| {label} | {sel.sum() / unseen.sum():.1%} | {np.sqrt(np.mean(d[sel] ** 2)) * 1e3:.2f} | "
                         f"{np.sum(d[sel] ** 2) / total:.1%} | {outside[sel].mean():.0%} |")

    row("on the table (faces down, < 0.5 mm up)", (nz < -0.9) & (height < 0.0005))
    rest = ~((nz < -0.9) & (height < 0.0005))
    for lo, hi in ((0, 0.002), (0.002, 0.01), (0.01, np.inf)):
        row(f"{lo * 1e3:.0f}-{hi * 1e3:.0f} mm over the table", rest & (height >= lo) & (height < hi))
    for lo, hi, name in ((-1.01, -0.5, "faces down"), (-0.5, 0.5, "faces sideways"), (0.5, 1.01, "faces up")):
        row(f"true normal {name}", rest & (nz >= lo) & (nz < hi))
    if mesh.observed is not None:
        observed = mesh.observed[corners].all(axis=1)
        carved = (mesh.carved[corners].all(axis=1) if mesh.carved is not None else np.zeros(len(P), bool)) & ~observed
        row("triangle observed (every corner)", observed)
        row("triangle on the carved hull (every corner)", carved)
        row("triangle guessed (the rest)", ~observed & ~carved)
    return lines


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sessions", nargs="+", help="processed simulated session folders")
    parser.add_argument("--hull", action="store_true", help="also the true unseen surface's distance to the hull")
    args = parser.parse_args()
    for folder in args.sessions:
        print("\n".join(breakdown(folder) + (hull_bound(folder) if args.hull else [])) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
