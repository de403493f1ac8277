"""From an acquired session to one mesh: decode and triangulate every view, register the views seeded by
the turntable angles, fuse, measure against the truth on the simulator, report (the work behind
``rangekit process`` and the end of ``rangekit scan``).

Writes into the session folder (atomically):

    view_NNN/cloud.ply, maps.npz, cloud.json   each view's cloud, its decoded maps and depth (cache)
    poses.json                                 registered poses, world = the first view's frame
    merged.ply, mesh.ply                       all views in one frame; the fused watertight mesh
    summary.json                               what the end-of-run summary prints, as data
    report.html                                the visual report (rangekit.app.report)

A view's cloud is reused when ``cloud.json`` says it was made with the same settings, so processing
that was interrupted (or rerun with another fusion method) does not decode again, and gives the same
mesh as an uninterrupted run.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from rangekit import __version__
from rangekit.app.acquire import SessionView, load_session
from rangekit.formats.capture import list_images, read_stack
from rangekit.errors import ConfigError
from rangekit.geometry import apply_T, compose, invert_T
from rangekit.io import atomic_save_npz, atomic_write_json, read_json
from rangekit.coded.patterns import PatternSpec
from rangekit.formats.clouds import load_cloud, save_cloud
from rangekit.surface.cloud import PointCloud, merge_clouds
from rangekit.formats.poses import save_poses
from rangekit.progress import StageTimer, call_progress
from rangekit.app.reconstruct import reconstruct_view
from rangekit.rig import Rig, load_rig

__all__ = ["FUSION_METHODS", "ProcessResult", "process_session"]

FUSION_METHODS = ("poisson", "tsdf")


@dataclass(frozen=True, eq=False)
class ProcessResult:
    """What processing a session produced. Distances in metres, times in seconds."""

    folder: Path
    view_names: list[str]
    T_world_view: np.ndarray        # (n, 4, 4) registered poses, world = first view
    n_points: list[int]             # points per view after filtering
    edges: list[dict]               # view graph: i, j, rmse, overlap, accepted, rotation/translation residual
    registration_rmse: float        # joint point-to-plane RMS of the final poses
    mesh: dict                      # vertices, triangles, watertight, area_m2, volume_m3, fusion
    seconds: dict = field(default_factory=dict)   # wall time per stage
    accuracy: dict | None = None    # simulator only: rangekit.sim.evaluate.Accuracy.to_dict()

    @property
    def mesh_path(self) -> Path:
        return self.folder / "mesh.ply"

    @property
    def mesh_watertight(self) -> bool:
        return bool(self.mesh["watertight"])

    def to_dict(self) -> dict:
        return {"schema": "rangekit.summary/1", "views": self.view_names, "n_points": self.n_points,
                "T_world_view": self.T_world_view.tolist(), "edges": self.edges,
                "registration_rmse_m": self.registration_rmse, "mesh": self.mesh, "seconds": self.seconds,
                "accuracy": self.accuracy}

    def summary_lines(self) -> list[str]:
        """The end-of-run summary, one line per fact, for people."""
        acc = [e for e in self.edges if e["accepted"]]
        rot = [e["rotation_residual_deg"] for e in acc if e.get("rotation_residual_deg") is not None]
        tr = [e["translation_residual_mm"] for e in acc if e.get("translation_residual_mm") is not None]
        m = self.mesh
        lines = [f"views: {len(self.view_names)}, points: {sum(self.n_points):,} "
                 f"({min(self.n_points):,} to {max(self.n_points):,} per view)",
                 f"registration: {len(acc)}/{len(self.edges)} pairs accepted, pair ICP RMSE median "
                 f"{np.median([e['rmse_mm'] for e in acc]):.4f} mm, joint RMS {self.registration_rmse * 1e3:.4f} mm"
                 + (f"; synchronisation residual max {max(rot):.4f} deg, {max(tr):.4f} mm" if rot and tr else ""),
                 f"mesh ({m['fusion']}): {m['vertices']:,} vertices, {m['triangles']:,} triangles, watertight "
                 f"{m['watertight']}, area {m['area_m2'] * 1e4:.1f} cm^2"
                 + (f", volume {m['volume_m3'] * 1e6:.1f} cm^3" if m["volume_m3"] is not None else ""),
                 "time: " + ", ".join(f"{k} {v:.1f} s" for k, v in self.seconds.items())]
        if self.accuracy:
            a = self.accuracy
            lines.append(f"accuracy against the true surface: RMS {a['rms'] * 1e3:.3f} mm "
                         f"({a['rms'] / a['diagonal']:.3%} of the {a['diagonal'] * 1e3:.0f} mm diagonal), 95th "
                         f"percentile {a['p95'] * 1e3:.3f} mm; completeness {a['completeness']:.1%} of the visible "
                         f"surface within {a['tolerance'] * 1e3:g} mm")
            lines.append(f"  ({a['visible_fraction']:.0%} of the object is visible within "
                         f"{a['max_incidence_deg']:g} deg of incidence; the other {a['unobserved_area']:.0%} of the "
                         f"mesh is filled in where no view looked, RMS {a['unobserved_rms'] * 1e3:.2f} mm there)")
        return lines

    def __repr__(self) -> str:
        t = ", ".join(f"{k} {v:.1f} s" for k, v in self.seconds.items())
        return (f"ProcessResult({len(self.n_points)} views, {sum(self.n_points)} points, mesh watertight "
                f"{self.mesh_watertight}; {t})")


def _view_cloud(v: SessionView, spec: PatternSpec, rig: Rig, settings: dict, full_scale: float | None,
                T_table_world: np.ndarray | None, table_margin: float) -> PointCloud:
    """Decode, triangulate and filter one view, or reuse its cache when made with the same settings."""
    meta = v.folder / "cloud.json"
    if meta.exists() and (v.folder / "cloud.ply").exists() and (v.folder / "maps.npz").exists():
        try:
            if read_json(meta, what="view cache").get("settings") == settings:
                return load_cloud(v.folder / "cloud.ply")
        except ConfigError:
            pass  # a damaged cache is rebuilt
    images = read_stack(list_images(v.folder))
    rec = reconstruct_view(images, spec, rig.camera, rig.projector, method=settings["method"],
                           full_scale=full_scale, response=rig.projector_response)
    xyz = rec.triangulated.xyz.copy()
    valid = np.isfinite(xyz[:, :, 0])
    c = rec.cloud
    if T_table_world is not None:
        keep = apply_T(T_table_world, c.points)[:, 2] > table_margin
        idx = np.flatnonzero(valid.ravel())
        valid.ravel()[idx[~keep]] = False
        c = PointCloud(c.points[keep], c.colours[keep], c.normals[keep])
    # Normals as stored (float32), so a run from the cache and a fresh one see the same numbers.
    c = PointCloud(c.points, c.colours, c.normals.astype(np.float32))
    depth = np.full(valid.shape, np.nan, dtype=np.float32)
    depth[valid] = apply_T(invert_T(rig.camera.T_world_cam), xyz[valid])[:, 2]
    save_cloud(v.folder / "cloud.ply", c)
    atomic_save_npz(v.folder / "maps.npz", proj_col=rec.decoded.proj_col.astype(np.float32),
                    confidence=rec.decoded.confidence.astype(np.float32), depth=depth)
    atomic_write_json(meta, {"settings": settings, "points": len(c)})
    return c


def process_session(folder: str | Path, *, fusion: str = "poisson", method: str = "auto",
                    table_margin: float = 0.002, evaluate: bool = True, report: bool = True,
                    progress: Callable | None = None) -> ProcessResult:
    """Process the completed views of a session into ``mesh.ply`` (and ``summary.json``, ``report.html``).

    Parameters
    ----------
    fusion : "poisson" (screened Poisson on the merged oriented cloud, the default and the more accurate)
        or "tsdf" (truncated signed distance volume of the registered depth maps).
    method : triangulation, see :func:`rangekit.app.reconstruct.reconstruct_view`.
    table_margin : points within this many metres above the turntable top (or below it) are dropped,
        so the table does not become part of the object.
    evaluate : on a simulated session, measure the mesh against the true surface.
    report : write ``report.html``.
    progress : ``progress(msg, done=None, total=None)`` (see :mod:`rangekit.progress`).
    """
    from rangekit.formats.meshes import save_mesh
    from rangekit.surface.fusion import poisson_mesh, tsdf_fuse
    from rangekit.registration.multiview import register_views

    if fusion not in FUSION_METHODS:
        raise ConfigError(f"fusion must be one of {', '.join(FUSION_METHODS)}, found {fusion!r}")
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
    settings = {"rangekit": __version__, "method": method, "table_margin": table_margin,
                "pattern": spec.to_dict()["method"], "full_scale": full_scale,
                "projector_response": None if rig.projector_response is None else rig.projector_response.to_dict()}
    timer = StageTimer()

    with timer.stage("decode"):
        clouds = []
        for k, v in enumerate(views):
            clouds.append(_view_cloud(v, spec, rig, settings, full_scale, T_table_world, table_margin))
            call_progress(progress, f"decoded {v.folder.name}: {len(clouds[-1]):,} points", k + 1, len(views))

    with timer.stage("register"):
        # Turntable prior: view k saw the object turned by M_k, so view k maps into view 0 by M_0 inv(M_k).
        prior = None
        if rig.T_world_table is not None:
            M = [rig.T_world_rotated(v.angle) for v in views]
            prior = np.stack([compose(M[0], invert_T(Mk)) for Mk in M])
        res = register_views(clouds, init_T_world_view=prior, progress=progress)
        names = [v.folder.name for v in views]
        save_poses(out / "poses.json", names, res.T_world_view,
                   world=f"frame of {views[0].folder.name} (the rig's world at its turntable angle)")
        edges, k_acc = [], 0
        for e in res.edges:
            row = {"i": e.i, "j": e.j, "rmse_mm": e.rmse * 1e3, "overlap": e.overlap, "accepted": e.accepted,
                   "reason": e.reason, "rotation_residual_deg": None, "translation_residual_mm": None}
            if e.accepted and k_acc < len(res.sync.edge_rotation_error):
                row["rotation_residual_deg"] = float(np.degrees(res.sync.edge_rotation_error[k_acc]))
                row["translation_residual_mm"] = float(res.sync.edge_translation_error[k_acc] * 1e3)
                k_acc += 1
            edges.append(row)

    with timer.stage("fuse"):
        T = res.T_world_view
        merged = merge_clouds(clouds, T)
        save_cloud(out / "merged.ply", merged)
        call_progress(progress, f"fusing {len(merged):,} points ({fusion})")
        if fusion == "poisson":
            step = max(1, len(merged) // 400_000)
            # One thread: Open3D's multi-threaded Poisson is not deterministic, and a resumed scan must
            # give the same mesh as an uninterrupted one (on 2 cores it is no slower).
            mesh = poisson_mesh(PointCloud(merged.points[::step], merged.colours[::step], merged.normals[::step]),
                                depth=9, n_threads=1)
        else:
            # Each view's camera-frame depth map as stored, seen by the camera at its registered pose.
            mesh = tsdf_fuse([(np.load(v.folder / "maps.npz")["depth"], None,
                               rig.camera.with_pose(compose(Tk, rig.camera.T_world_cam))) for v, Tk in zip(views, T)])
        save_mesh(out / "mesh.ply", mesh)
        mesh_info = {"vertices": len(mesh.vertices), "triangles": len(mesh.triangles),
                     "watertight": bool(mesh.is_watertight), "area_m2": float(mesh.area),
                     "volume_m3": float(abs(mesh.volume)) if mesh.is_watertight else None, "fusion": fusion}
        call_progress(progress, f"mesh: {len(mesh.vertices):,} vertices, {len(mesh.triangles):,} triangles, "
                                f"watertight {mesh.is_watertight}")

    accuracy, truth = None, None
    sim_info = data.get("simulator")
    if evaluate and sim_info:
        with timer.stage("evaluate"):
            from rangekit.surface.mesh import TriangleMesh
            from rangekit.sim import default_scene
            from rangekit.sim.evaluate import mesh_accuracy

            call_progress(progress, "measuring the mesh against the true surface")
            scene = default_scene(sim_info["object"])
            acc = mesh_accuracy(mesh, scene, rig, [v.angle for v in views])
            accuracy = acc.to_dict()
            # The true surface in the session world (the table at the first view's angle), for the heat map.
            obj = scene.objects[0]
            M0 = rig.T_world_rotated(views[0].angle) if rig.T_world_table is not None else np.eye(4)
            truth = TriangleMesh(apply_T(M0, obj.world_vertices()), obj.triangles)

    result = ProcessResult(out, names, res.T_world_view, [len(c) for c in clouds], edges, float(res.rmse),
                           mesh_info, timer.seconds, accuracy)
    if report:
        with timer.stage("report"):
            from rangekit.app.report import write_report

            call_progress(progress, "writing report.html")
            write_report(out, result, clouds=clouds, merged=merged, mesh=mesh, session=data, rig=rig,
                         truth=truth, progress=progress)
    atomic_write_json(out / "summary.json", result.to_dict())
    return result
