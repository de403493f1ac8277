"""From a laser-line session to one mesh: each step's line peaks triangulated against their laser planes,
each profile turned back by its turntable angle into one frame, the lasers merged, filtered and fused
(the laser branch of :func:`rangekit.app.process.process.process_session`).

No registration: a profile is a curve, too thin to register, and the calibrated turntable places it
(Fusiello 13.2.4). The world is the first step's frame, as for coded light, so the poses, the accuracy
and the report read the same.

Per step (``view_NNN``, a laser capture folder): peaks of every laser (laser on minus laser off), each
peak's ray (with the lens distortion) met with that laser's plane, points within ``table_margin`` of the
turntable top dropped (the line on the table is not even looked for: each laser's peaks are searched
only where its plane lies above the table top, :func:`rangekit.laser.triangulate.plane_region`), points
off a continuous run of the line dropped (:mod:`rangekit.laser.profile_filter`), the rest turned by
``turntable_prior`` into the world. Normals are estimated on the merged cloud and turned towards the
camera centre each point was seen from, then screened Poisson.

A laser that gives no line in any step is a :class:`~rangekit.errors.DecodeError` naming the laser and
its frames (laser off, unplugged, or aimed beside the object), never an empty cloud; so is a laser whose
lines all fall on the turntable top (the object missing or out of view) and a laser whose line is
saturated in at least :data:`SATURATED_SHARE` of the rows where it was seen (power or exposure too high).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from rangekit.app.laser.reconstruct import reconstruct_laser_capture
from rangekit.app.process.options import ProcessOptions
from rangekit.errors import ConfigError, DecodeError
from rangekit.formats.clouds import save_cloud
from rangekit.formats.poses import save_poses
from rangekit.formats.sessions.laser_summary import LaserFigures, LaserSummary
from rangekit.formats.sessions.summary import ProcessResult
from rangekit.formats.laser_capture import load_laser_capture
from rangekit.formats.sessions.session import Session
from rangekit.geometry import apply_T, invert_T
from rangekit.laser.triangulate import plane_region
from rangekit.io import atomic_write_json
from rangekit.progress import call_progress
from rangekit.rig.rig_file import turntable_prior
from rangekit.surface.cloud import PointCloud
from rangekit.formats.sessions.files import (MERGED_FILE, MESH_FILE, POSES_FILE, REPORT_FILE, SUMMARY_FILE,
                                             WATERTIGHT_FILE)

__all__ = ["LaserProfiles", "laser_profiles", "oriented_profiles", "profile_spacing", "process_laser", "SATURATED_SHARE"]

#: A laser saturated in this share of the rows where its line was seen (saturated rows over saturated
#: rows plus the points kept on the object) is an error: the scan's power or exposure is wrong, not a shiny patch.
SATURATED_SHARE = 0.9


@dataclass(frozen=True, eq=False)
class LaserProfiles:
    """Every step's points in the session world (the first step's frame).

    cloud : merged points, colours from the laser-off images (no normals yet).
    step : (N,) int, the step (view index in ``names``) of each point; laser : (N,) int, which laser lit it.
    origins : (n_steps, 3) the camera centre of each step in the world (the points' sensor, for normals).
    T_world_view : (n_steps, 4, 4) each step's turntable pose in the world.
    names : the steps' folder names; n_points : (n_steps, n_lasers) points per step and laser.
    rejected : per laser, rows rejected over the scan by reason (saturated, double, ...).
    on_table : (n_lasers,) int, points per laser dropped as the turntable top (within ``table_margin``; the
        region mask keeps most of the table's line out; for a laser without a line above the table, the
        points a few steps give on the table without the mask).
    """

    cloud: PointCloud
    step: np.ndarray
    laser: np.ndarray
    origins: np.ndarray
    T_world_view: np.ndarray
    names: list[str]
    n_points: np.ndarray
    rejected: list[dict]
    on_table: np.ndarray | None = None


def laser_profiles(session: Session, *, method: str = "gaussian", table_margin: float = 0.002,
                   progress: Callable | None = None, map_steps: Callable | None = None) -> LaserProfiles:
    """Triangulate every done step of a laser ``session`` into the world (see the module docstring).
    ``map_steps(fn, steps)``: ``fn`` of each step, in order (the runner's map over views,
    :meth:`rangekit.app.runner.Runner.map_views`); None: one after another here.

    Raises DecodeError when a laser lights nothing but the turntable top in every step, or is saturated in
    :data:`SATURATED_SHARE` of its rows (naming it, its frames and what to change), FileFormatError for an
    unreadable frame (naming it).
    """
    rig, views = session.rig, session.done_views
    full_scale = session.capture.full_scale
    T_world_view = (turntable_prior(rig.T_world_table, [v.angle for v in views]) if rig.T_world_table is not None
                    else np.repeat(np.eye(4)[None], len(views), axis=0))
    T_table_world = invert_T(rig.T_world_table) if rig.T_world_table is not None else None
    # Where each laser's line may be: its plane above the table top. The line on the table is not looked
    # at, so in the rows it shares with the object's line the row is not "double".
    regions = None if T_table_world is None else [
        plane_region(rig.camera, laser, rig.T_world_table, z_min=table_margin) for laser in rig.lasers]

    def one(k: int, masks=regions):
        v = views[k]
        rec = reconstruct_laser_capture(load_laser_capture(v.folder, rig=rig), method=method, full_scale=full_scale,
                                        require=False, regions=masks)
        P, colours, which = rec.cloud.points, rec.cloud.colours, rec.laser_index
        table = np.zeros(len(rig.lasers), dtype=np.int64)
        if T_table_world is not None and len(P):
            keep = apply_T(T_table_world, P)[:, 2] > table_margin
            table = np.bincount(which[~keep], minlength=len(rig.lasers))
            P, colours, which = P[keep], colours[keep], which[keep]
        n = np.bincount(which, minlength=len(rig.lasers))   # points per laser after the table filter
        return apply_T(T_world_view[k], P), colours, which, n, [p.rejected for p in rec.peaks], table

    points, colours, steps, lasers, counts, rejected = [], [], [], [], [], [{} for _ in rig.lasers]
    on_table = np.zeros(len(rig.lasers), dtype=np.int64)
    for k, (P, C, which, n, rej, table) in enumerate((map_steps or map)(one, range(len(views)))):
        on_table += table
        points.append(P)
        colours.append(C)
        lasers.append(which)
        steps.append(np.full(len(P), k, dtype=np.int64))
        counts.append(n)
        for total, r in zip(rejected, rej):
            for reason, m in r.items():
                total[reason] = total.get(reason, 0) + int(m)
        if (k + 1) % 20 == 0 or k + 1 == len(views):
            call_progress(progress, f"laser profiles: {k + 1}/{len(views)} steps, "
                                    f"{sum(len(p) for p in points):,} points", k + 1, len(views))
    n_points = np.asarray(counts, dtype=np.int64).reshape(len(views), len(rig.lasers))
    if regions is not None and (n_points.sum(axis=0) == 0).any():
        # A laser without a line above the table: is there one on the table (no object)? A few steps tell.
        for k in sorted({0, len(views) // 2, len(views) - 1}):
            on_table += one(k, None)[5]

    def frames(i: int) -> str:
        return f"{views[0].folder / f'laser{i}.png'} ... {views[-1].folder.name}"

    for i, laser in enumerate(rig.lasers):
        n_i, saturated = int(n_points[:, i].sum()), int(rejected[i].get("saturated", 0))
        if saturated and saturated >= SATURATED_SHARE * (saturated + n_i):
            raise DecodeError(f"laser {i} ({laser.name}): the line is saturated in {saturated:,} rows over "
                              f"{len(views)} steps ({frames(i)}) and only {n_i:,} points on the object could be "
                              f"placed ({saturated / (saturated + n_i):.0%} of the two saturated, "
                              f"under {SATURATED_SHARE:.0%} accepted); lower the laser power or the camera's exposure (or "
                              "gain) and scan again")
        if n_i == 0 and on_table[i]:
            raise DecodeError(f"laser {i} ({laser.name}): its line was found in the {len(views)} steps "
                              f"({frames(i)}) only on the turntable top ({int(on_table[i]):,} points on it "
                              f"within {table_margin * 1e3:g} mm of it, dropped as table points): no object "
                              "was scanned; is the object on the turntable, in the camera's view and in the "
                              "laser's plane?")
        if n_i == 0:
            why = "; ".join(f"{m} {reason}" for reason, m in rejected[i].items() if m) or "no line above the noise"
            raise DecodeError(f"laser {i} ({laser.name}): no line in any of the {len(views)} steps "
                              f"({frames(i)}); rows rejected: "
                              f"{why}. Is the laser on (its switch {laser.switch or i + 1}), aimed at the object, "
                              "and the object in view?")
    origins = T_world_view[:, :3, :3] @ rig.camera.center + T_world_view[:, :3, 3]   # (n_steps, 3)
    cloud = PointCloud(np.concatenate(points), colours=np.concatenate(colours))
    return LaserProfiles(cloud, np.concatenate(steps), np.concatenate(lasers), origins, T_world_view,
                         [v.folder.name for v in views], n_points, rejected, on_table)


def oriented_profiles(profiles: LaserProfiles, *, k: int = 20) -> PointCloud:
    """The merged cloud with normals from ``k`` neighbours, each turned towards the camera centre of its
    point's step.

    No statistical outlier filter: the ghosts it was meant for are gone with the profile filter, and on
    the 400-step lumpy scan it dropped 4,417 good points of sparse, grazing parts (undersides), opening
    holes that Poisson bridged 3-28 mm off the surface (mesh RMS 0.18 mm against 0.029 mm without it)."""
    from rangekit.surface.cloud import estimate_normals, orient_normals_to_sensor

    P = profiles.cloud.points
    normals = orient_normals_to_sensor(P, estimate_normals(P, k=k), profiles.origins[profiles.step])
    return PointCloud(P, colours=profiles.cloud.colours, normals=normals)


def profile_spacing(profiles: LaserProfiles, T_world_table: np.ndarray | None) -> np.ndarray:
    """(N,) metres: each point's sampling distance for :func:`rangekit.surface.observed.observed_vertices`: the
    larger of its mean distance to its 6 nearest neighbours (along its own line, mostly) and the arc a
    turntable step moves it (its distance from the turntable axis times the median step angle), the gap
    between two profiles that the nearest neighbours do not see. ``T_world_table``: the rig's turntable
    (its z axis is the rotation axis, in the session world too: a turn about the axis keeps it); None:
    the nearest-neighbour spacing alone."""
    from rangekit.surface.observed import point_spacing

    P = profiles.cloud.points
    s = point_spacing(P)
    T = profiles.T_world_view
    if len(T) < 2 or T_world_table is None:
        return s
    # Step angle: the rotation between consecutive steps' poses; axis: their common rotation axis.
    R = np.einsum("kji,kjl->kil", T[:-1, :3, :3], T[1:, :3, :3])
    angles = np.arccos(np.clip((np.trace(R, axis1=1, axis2=2) - 1) / 2, -1.0, 1.0))
    step = float(np.median(angles))
    if step <= 0:
        return s
    local = apply_T(invert_T(T_world_table), P)
    return np.maximum(s, np.hypot(local[:, 0], local[:, 1]) * step)


def process_laser(session: Session, options: ProcessOptions, evaluate, runner,
                  method: str = "gaussian") -> ProcessResult:
    """The laser branch of :func:`rangekit.app.process.process.process_session` (same outputs, same set rule:
    ``summary.json`` last; stages PROFILES, FUSE, EVALUATE, REPORT timed and announced by ``runner``
    (:class:`rangekit.app.runner.Runner`), each mesh as :class:`rangekit.app.events.MeshReady`).
    ``evaluate(mesh, angles, cloud=points)`` also measures the merged cloud."""
    from rangekit.app.events import MeshReady, Stage
    from rangekit.app.process.fused_outputs import evaluate_fused, save_fused
    from rangekit.surface.fusion import poisson_meshes

    out, fusion, table_margin, progress = session.folder, options.fusion, options.table_margin, runner.progress
    if fusion != "poisson":
        raise ConfigError(f"--fusion {fusion}: a laser scan has profiles, not depth maps; it fuses with poisson")
    timer = runner
    with timer.stage(Stage.PROFILES):
        profiles = laser_profiles(session, method=method, table_margin=table_margin, progress=progress,
                                  map_steps=runner.map_views)
        save_poses(out / POSES_FILE, profiles.names, profiles.T_world_view,
                   world=f"frame of {profiles.names[0]} (the rig's world at its turntable angle); each step "
                         "placed by its turntable angle")
    with timer.stage(Stage.FUSE):
        call_progress(progress, f"normals of {len(profiles.cloud):,} points")
        merged = oriented_profiles(profiles)
        save_cloud(out / MERGED_FILE, merged)
        call_progress(progress, f"fusing {len(merged):,} points (poisson)")
        depth, most = options.poisson(laser=True)      # the laser's own by default: depth 9, 400k points
        step = max(1, len(merged) // most)
        # One thread: Open3D's multi-threaded Poisson is not deterministic (see process.py).
        fused = poisson_meshes(PointCloud(merged.points[::step], merged.colours[::step], merged.normals[::step]),
                               depth=depth, n_threads=1,
                               spacing=profile_spacing(profiles, session.rig.T_world_table)[::step])
        mesh_info, watertight_info = save_fused(out, fused, fusion, options.mesh_format)
        mesh = fused.observed
        runner.emit(MeshReady("observed", out / MESH_FILE, mesh))
        runner.emit(MeshReady("watertight", out / WATERTIGHT_FILE, fused.watertight))
    angles = [v.angle for v in session.done_views]
    accuracy, truth = None, None
    if evaluate is not None:
        with timer.stage(Stage.EVALUATE):
            call_progress(progress, "measuring the cloud and the meshes against the true surface")
            accuracy, truth, _ = evaluate_fused(evaluate, fused, angles, cloud=merged.points)
    per_step = profiles.n_points.sum(axis=1)
    laser_info = LaserSummary(tuple(LaserFigures(laser.name, int(profiles.n_points[:, i].sum()),
                                                 int((profiles.n_points[:, i] == 0).sum()), int(profiles.on_table[i]),
                                                 profiles.rejected[i])
                                    for i, laser in enumerate(session.rig.lasers)), method)
    result = ProcessResult(out, profiles.names, profiles.T_world_view, [int(n) for n in per_step], [], float("nan"),
                           mesh_info, timer.seconds, accuracy, laser=laser_info, watertight_mesh=watertight_info,
                           options=options.to_dict())
    if options.report:
        with timer.stage(Stage.REPORT):
            from rangekit.app.laser.report import write_laser_report

            call_progress(progress, f"writing {REPORT_FILE}")
            write_laser_report(out, result, profiles=profiles, merged=merged, mesh=mesh, session=session, truth=truth,
                               progress=progress, watertight=fused.watertight)
    atomic_write_json(out / SUMMARY_FILE, result.to_dict())   # last: the set is complete
    return result
