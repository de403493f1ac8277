"""From an acquired session to one mesh: decode and triangulate every view, register the views seeded by
the turntable angles, fuse (the work behind ``rangekit process`` and the end of ``rangekit scan``).

Writes into the session folder (atomically): ``view_NNN/cloud.ply``, ``poses.json`` (world = the first
view's frame), ``merged.ply`` and ``mesh.ply``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from rangekit.acquire import load_session
from rangekit.capture import list_images, read_stack
from rangekit.errors import ConfigError
from rangekit.geometry import apply_T, compose, invert_T
from rangekit.patterns import PatternSpec
from rangekit.pointcloud import PointCloud, save_cloud
from rangekit.poses import save_poses
from rangekit.reconstruct import reconstruct_view
from rangekit.rig import load_rig

__all__ = ["ProcessResult", "process_session"]


@dataclass(frozen=True, eq=False)
class ProcessResult:
    T_world_view: np.ndarray        # (n, 4, 4) registered poses, world = first view
    n_points: list[int]             # points per view after filtering
    mesh_path: Path
    mesh_watertight: bool
    seconds: dict = field(default_factory=dict)   # time per stage

    def __repr__(self) -> str:
        t = ", ".join(f"{k} {v:.1f} s" for k, v in self.seconds.items())
        return (f"ProcessResult({len(self.n_points)} views, {sum(self.n_points)} points, mesh watertight "
                f"{self.mesh_watertight}; {t})")


def process_session(folder: str | Path, *, method: str = "auto", table_margin: float = 0.002,
                    progress: Callable[[str], None] | None = None) -> ProcessResult:
    """Process the completed views of a session into ``mesh.ply``.

    ``table_margin``: points within this many metres above the turntable top (or below it) are dropped,
    so the table does not become part of the object.
    """
    from rangekit.mesh import poisson_mesh, save_mesh
    from rangekit.registration.multiview import register_views

    say = progress or (lambda msg: None)
    out = Path(folder)
    data, views = load_session(out)
    views = [v for v in views if v.done]
    if len(views) < 2:
        raise ConfigError(f"{out}: {len(views)} completed view(s); processing needs at least 2 (resume the scan)")
    rig = load_rig(out / "rig.json")
    spec = PatternSpec.from_dict(data["pattern"], where=f"{out}/session.json")
    bits = (data.get("simulator") or {}).get("imaging", {}).get("bits")
    full_scale = float((1 << bits) - 1) if bits else None
    T_table_world = invert_T(rig.T_world_table) if rig.T_world_table is not None else None
    seconds: dict[str, float] = {}

    t0 = time.perf_counter()
    clouds, n_points = [], []
    for k, v in enumerate(views):
        images = read_stack(list_images(v.folder))
        rec = reconstruct_view(images, spec, rig.camera, rig.projector, method=method, full_scale=full_scale)
        c = rec.cloud
        if T_table_world is not None:
            keep = apply_T(T_table_world, c.points)[:, 2] > table_margin
            c = PointCloud(c.points[keep], c.colours[keep], c.normals[keep])
        save_cloud(v.folder / "cloud.ply", c)
        clouds.append(c)
        n_points.append(len(c))
        say(f"decoded view {k + 1}/{len(views)}: {len(c)} points")
    seconds["decode"] = time.perf_counter() - t0

    # Turntable prior: view k saw the object turned by M_k, so view k maps into view 0 by M_0 inv(M_k).
    t0 = time.perf_counter()
    prior = None
    if rig.T_world_table is not None:
        M = [rig.T_world_rotated(v.angle) for v in views]
        prior = np.stack([compose(M[0], invert_T(Mk)) for Mk in M])
    res = register_views(clouds, init_T_world_view=prior, progress=say)
    save_poses(out / "poses.json", [v.folder.name for v in views], res.T_world_view,
               world=f"frame of {views[0].folder.name} (the rig's world at its turntable angle)")
    seconds["register"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    P = np.concatenate([c.points @ T[:3, :3].T + T[:3, 3] for c, T in zip(clouds, res.T_world_view)])
    N = np.concatenate([c.normals @ T[:3, :3].T for c, T in zip(clouds, res.T_world_view)])
    C = np.concatenate([c.colours for c in clouds])
    merged = PointCloud(P, C, N)
    save_cloud(out / "merged.ply", merged)
    step = max(1, len(P) // 400_000)
    mesh = poisson_mesh(PointCloud(P[::step], C[::step], N[::step]), depth=9)
    save_mesh(out / "mesh.ply", mesh)
    seconds["fuse"] = time.perf_counter() - t0
    say(f"mesh: {len(mesh.vertices)} vertices, {len(mesh.triangles)} triangles, watertight {mesh.is_watertight}")
    return ProcessResult(res.T_world_view, n_points, out / "mesh.ply", mesh.is_watertight, seconds)
