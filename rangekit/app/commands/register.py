"""Register scan files into one frame and fuse them: the work behind ``rangekit register``."""

from __future__ import annotations

import shlex
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from rangekit._runtime.arguments import check_bool, check_callable, check_items, check_number, check_path, check_text
from rangekit.app.commands.handedness import check_handedness
from rangekit.errors import ConfigError, RegistrationError, UsageError, naming
from rangekit.formats.clouds import load_cloud, save_cloud
from rangekit.surface.cloud import PointCloud, bbox_diagonal, check_voxel, merge_clouds
from rangekit.formats.poses import load_poses, save_poses
from rangekit.formats.stanford_conf import load_stanford_conf
from rangekit.registration.multiview import MultiViewOptions, MultiViewResult, register_views
from rangekit.registration.view_graph import ViewsCutOff
from rangekit.registration.pairs import all_pairs, nearest_and_long_links
from rangekit.rig.rig_file import table_frame, turntable_prior
from rangekit.formats.sessions.files import MERGED_FILE, MESH_FILE, POSES_FILE

__all__ = ["parse_init", "RegisterReport", "register"]


def parse_init(init: str | None, n: int, sources: Sequence[str]) -> np.ndarray | None:
    """Prior poses from ``none``, a poses.json file, a Stanford ``.conf`` file, or ``turntable:AX,AY,AZ:STEP_DEG[:PX,PY,PZ]``.

    turntable: view i is rotated by i * STEP degrees about the axis (AX, AY, AZ) through (PX, PY, PZ)
    (default the origin) of the first view's frame.
    """
    if init is None or init == "none":
        return None
    if init.startswith("turntable:"):
        parts = init.split(":")
        try:
            axis = np.array([float(v) for v in parts[1].split(",")])
            step = np.radians(float(parts[2]))
            point = np.array([float(v) for v in parts[3].split(",")]) if len(parts) > 3 else np.zeros(3)
            if (axis.shape != (3,) or point.shape != (3,) or not np.all(np.isfinite([*axis, *point, step]))
                    or not np.linalg.norm(axis) > 0 or not abs(step) <= 2 * np.pi or len(parts) > 4):
                raise ValueError
        except (ValueError, IndexError, OverflowError) as exc:
            raise UsageError(f"--init {init!r}: expected turntable:AX,AY,AZ:STEP_DEG[:PX,PY,PZ] with finite numbers, "
                             "a non-zero axis and a step of at most 360 degrees, e.g. turntable:0,1,0:24") from exc
        # View i is turned by +i * STEP: the prior of a table turning by -i * STEP between views.
        return turntable_prior(table_frame(axis, point), -step * np.arange(n))
    srcs, T = load_stanford_conf(init, expected=n) if init.endswith(".conf") else load_poses(init)
    if len(T) != n:
        raise ConfigError(f"{init}: has {len(T)} views, but {n} scans were given")
    names = [Path(s).name for s in sources]
    if [Path(s).name for s in srcs] != names:
        order = {Path(s).name: k for k, s in enumerate(srcs)}
        missing = [s for s in names if s not in order]
        if missing:
            raise ConfigError(f"{init}: no pose for {missing}")
        T = T[[order[s] for s in names]]
    return T


@dataclass(frozen=True, eq=False)
class RegisterReport:
    sources: list[str]
    result: MultiViewResult
    merged: PointCloud
    mesh_path: Path | None


def register(paths: Sequence[str | Path], out_dir: str | Path, *, init: str | None = None,
                   voxel: float | None = None, mesh: bool = True,
                   progress: Callable[[str], None] | None = None, neighbours: int | None = None) -> RegisterReport:
    """Read the scans, register them (world = first scan's frame), write poses.json, merged.ply and mesh.ply.

    ``neighbours``: the view graph's k (each view with its k nearest in rotation plus a few long links,
    and with no prior coarse alignment of its k most similar); 0 = every pair; None = register_views'
    defaults (k = 4; with a prior from a file or --init turntable:..., every pair)."""
    paths = check_items("paths", paths, "a list of cloud files", min_items=1)
    for k, p in enumerate(paths):
        check_path(f"paths[{k}]", p, what="a cloud file")
    check_path("out_dir", out_dir, what="a folder")
    check_text("init", init, what=f"prior poses (a {POSES_FILE}, a Stanford .conf or turntable:...)", optional=True)
    check_number("voxel", voxel, lo=0, lo_open=True, unit="metres", optional=True)
    check_bool("mesh", mesh)
    check_callable("progress", progress)
    check_number("neighbours", neighbours, lo=0, integer=True, optional=True)
    say = progress or (lambda msg: None)
    paths = [Path(p) for p in paths]
    clouds = []
    for p in paths:
        clouds.append(load_cloud(p))
        say(f"read {p.name}: {len(clouds[-1])} points")
    prior = parse_init(init, len(paths), [str(p) for p in paths])
    if voxel is not None:  # the caller's option, checked against the scans before any work
        check_voxel(voxel, bbox_diagonal(clouds), what=f"--voxel-mm {voxel * 1e3:g}", error=UsageError)
    graph = ({} if neighbours is None else dict(pairs=all_pairs, coarse_neighbours=None) if neighbours == 0 else
             dict(pairs=nearest_and_long_links(int(neighbours)), coarse_neighbours=int(neighbours)))
    options = MultiViewOptions(voxel=voxel, **graph)
    out = Path(out_dir)
    try:
        res = register_views(clouds, init_T_world_view=prior, options=options, progress=say,
                             names=[p.name for p in paths])
    except ViewsCutOff as cut:
        # Keep what can be registered: the other views, written as usual, then the error names the rest.
        keep = [k for k in range(len(paths)) if k not in cut.views]
        if len(keep) < 2:
            raise
        say(f"registering the other {len(keep)} views without {', '.join(paths[k].name for k in cut.views)}")
        report = _write(out, [paths[k] for k in keep], [clouds[k] for k in keep],
                        register_views([clouds[k] for k in keep],
                                       init_T_world_view=None if prior is None else prior[keep], options=options,
                                       progress=say, names=[paths[k].name for k in keep]), mesh, voxel, say)
        quoted = lambda ps: " ".join(shlex.quote(str(p)) for p in ps)  # noqa: E731
        alone = [paths[k] for k in cut.views]
        raise RegistrationError(
            f"{cut}. Wrote the other {len(keep)} views to {out} ({POSES_FILE}, {MERGED_FILE}"
            f"{', ' + MESH_FILE if report.mesh_path else ''}). To retry with every pair: rangekit register "
            f"{quoted(paths)} --neighbours 0 --out {shlex.quote(str(out) + '-all')}"
            + (f"; to register those on their own: rangekit register {quoted(alone)} --out "
               f"{shlex.quote(str(out) + '-rest')}" if len(alone) > 1 else "")) from None
    check_handedness(clouds, res, [p.name for p in paths], voxel=voxel, options=options)  # a mirrored scan
    return _write(out, paths, clouds, res, mesh, voxel, say)


def _write(out: Path, paths: list[Path], clouds: list[PointCloud], res: MultiViewResult, mesh: bool,
           voxel: float | None, say: Callable[[str], None]) -> RegisterReport:
    """poses.json, merged.ply and (``mesh``) mesh.ply of the registered ``clouds`` into ``out``."""
    out.mkdir(parents=True, exist_ok=True)
    edges_of = {k: [e for e in res.edges if e.accepted and k in (e.i, e.j)] for k in range(len(paths))}
    extra = [{"edges": len(edges_of[k]),
              "mean_edge_rmse_m": float(np.mean([e.rmse for e in edges_of[k]])) if edges_of[k] else None,
              # Edges whose overlap left motions free: the prior was kept along them (not measured).
              "prior_kept": [f"{e.i}-{e.j}: {e.unconstrained}" for e in edges_of[k] if e.unconstrained]}
             for k in range(len(paths))]
    save_poses(out / POSES_FILE, [str(p) for p in paths], res.T_world_view, extra=extra)
    merged = merge_clouds(clouds, res.T_world_view)
    save_cloud(out / MERGED_FILE, merged)
    mesh_path = None
    if mesh:
        from rangekit.formats.meshes import save_mesh
        from rangekit.surface.cloud import oriented_normals_cloud
        from rangekit.surface.fusion import poisson_mesh

        say("meshing (screened Poisson)")
        with naming(out / MERGED_FILE):  # the merged scans: too flat or too few to close (use --no-mesh)
            m = poisson_mesh(merged if merged.normals is not None
                             else oriented_normals_cloud(merged.points, voxel=voxel))
        mesh_path = out / MESH_FILE
        save_mesh(mesh_path, m)
    return RegisterReport([str(p) for p in paths], res, merged, mesh_path)
