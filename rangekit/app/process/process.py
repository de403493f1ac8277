"""From an acquired session to one mesh: decode and triangulate every view, register the views seeded by
the turntable angles, fuse, measure against the truth when given an evaluator, report (the work behind
``rangekit process`` and the end of ``rangekit scan``). The pipeline is the same on hardware and on
the simulator: it never imports :mod:`rangekit.sim` (see :func:`rangekit.app.scan.scan.session_evaluator`).

Writes into the session folder (atomically):

    view_NNN/cloud.ply, maps.npz, cloud.json   each view's cloud, its decoded maps and depth (cache,
                                               rangekit.app.process.view_cache)
    poses.json                                 registered poses, world = the first view's frame
    merged.ply                                 all views in one frame
    mesh.ply, mesh_watertight.ply              the fused surface the views observed (open), and closed with
                                               a per-vertex ``observed`` flag (rangekit.app.process.fused_outputs)
    summary.json                               what the end-of-run summary prints, as data
    report.html                                the visual report (rangekit.app.report.page)

A view's cloud is reused when ``cloud.json`` says it was made with the same settings, so processing
that was interrupted (or rerun with another fusion method) does not decode again, and gives the same
mesh as an uninterrupted run.

The outputs are written as a set: a stale ``summary.json`` is removed first and the new one written
last, so a folder with ``summary.json`` always has the mesh, poses and merged cloud of the same run.
Processing holds the session's lock and first checks every view's frames against their recorded
SHA-256s (:func:`rangekit.formats.sessions.check.verify_views`).
"""

from __future__ import annotations

from contextlib import ExitStack
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Protocol, Sequence

import numpy as np

from rangekit.app.process.view_cache import ViewMaps, cache_settings, reload_maps, table_transform, view_clouds
from rangekit.camera import forget_pixel_rays
from rangekit._runtime.child import call_beside, spawn_child
from rangekit.errors import ConfigError
from rangekit.formats.clouds import save_cloud
from rangekit.formats.poses import save_poses
from rangekit.formats.sessions.session import Session
from rangekit.formats.sessions.check import verify_views
from rangekit.formats.sessions.lock import session_lock
from rangekit.formats.sessions.summary import ProcessResult
from rangekit.geometry import compose
from rangekit.io import atomic_write_json, fsync_folder
from rangekit._runtime.memory import release_free_memory, reuse_freed_memory
from rangekit.progress import StageTimer, call_progress
from rangekit.rig.rig_file import Rig, turntable_prior
from rangekit.surface.cloud import PointCloud, merge_clouds, view_index
from rangekit._runtime.threads import one_blas_thread

if TYPE_CHECKING:
    from rangekit.registration.pair_refine import PairMapper

__all__ = ["FUSION_METHODS", "Evaluation", "Evaluator", "process_session"]

FUSION_METHODS = ("poisson", "tsdf")

#: Fewest sampled points whose Poisson runs in a child process: below, it takes less than the child's start
#: (about 1 s of imports, on the other core).
CHILD_MIN_POINTS = 100_000
#: Poisson's input: every k-th merged point, k the smallest that leaves at most this many.
POISSON_POINTS = 400_000
#: What the Poisson child imports while the views are registered (Open3D alone: 0.6 s).
CHILD_IMPORTS = ("open3d", "rangekit.surface.fusion")


class Evaluation(Protocol):
    """What an evaluator returns: ``accuracy`` (an object with ``to_dict()``, the summary's "accuracy"),
    ``truth`` (the true surface as a TriangleMesh in the session world, for the report's heat map) and
    ``view_errors`` (a list of per-view dicts, the summary's "view_errors", or None)."""

    accuracy: object
    truth: object
    view_errors: list | None


#: ``evaluate(mesh, angles, cloud=None, views=None)``: the fused mesh (session world) and the views'
#: turntable angles (radians) to an :class:`Evaluation`; ``cloud`` the merged points (session world),
#: ``views`` a dict of the views' ``clouds``, registered ``T_world_view``, decoded ``proj_cols`` and
#: ``names`` for the per-view breakdown. An evaluator may have ``prepare(angles, views)``, run beside the
#: fusion, after which ``views["proj_cols"]`` is emptied (made into the per-view errors, not kept).
#: The simulator provides one (:func:`rangekit.sim.truth.evaluate.truth_evaluator`).
Evaluator = Callable[[object, Sequence[float]], Evaluation]


def process_session(folder: str | Path, *, fusion: str = "poisson", method: str = "auto",
                    table_margin: float = 0.002, evaluate: Evaluator | None = None, report: bool = True,
                    progress: Callable | None = None, map_pairs: PairMapper | None = None) -> ProcessResult:
    """Process the completed views of a session into ``mesh.ply`` (the observed surface) and
    ``mesh_watertight.ply`` (closed, flagged; and ``summary.json``, ``report.html``).

    Parameters
    ----------
    fusion : "poisson" (screened Poisson on the merged oriented cloud, the default and the more accurate)
        or "tsdf" (truncated signed distance volume of the registered depth maps).
    method : triangulation, see :func:`rangekit.coded.reconstruct.reconstruct_view`.
    table_margin : points within this many metres above the turntable top (or below it) are dropped,
        so the table does not become part of the object.
    evaluate : measures the mesh against the truth (see :data:`Evaluator`); None on hardware. Processing
        itself never imports the simulator.
    report : write ``report.html``.
    progress : ``progress(msg, done=None, total=None)`` (see :mod:`rangekit.progress`).
    map_pairs : runs the registration's pair refinements (:func:`rangekit.registration.multiview.register_views`;
        the Dask batch maps them onto its workers); None: here, one after another.

    Raises
    ------
    FileFormatError
        A view's frames differ from the SHA-256s recorded in session.json (changed, missing, extra).
    SessionLocked
        Another process is working on the session.
    """
    if fusion not in FUSION_METHODS:
        raise ConfigError(f"fusion must be one of {', '.join(FUSION_METHODS)}, found {fusion!r}")
    out = Path(folder)
    if not (out / "session.json").is_file():
        raise ConfigError(f"{out}: not a session folder (no session.json)")
    with session_lock(out), one_blas_thread(), ExitStack() as children:   # thin products: rangekit._runtime.threads
        return _process(out, fusion, method, table_margin, evaluate, report, progress, map_pairs, children)


def _process(out: Path, fusion: str, method: str, table_margin: float, evaluate: Evaluator | None, report: bool,
             progress: Callable | None, map_pairs: PairMapper | None, children: ExitStack) -> ProcessResult:
    from rangekit.app.process.fused_outputs import MESH_FILE, WATERTIGHT_FILE, evaluate_observed, save_one, with_closed
    from rangekit.registration.multiview import MultiViewOptions, register_views
    from rangekit.surface.fusion import poisson_input, poisson_surfaces
    from rangekit.surface.observed import observed_rule
    from rangekit.surface.watertight import make_watertight

    session = Session.load(out)
    views = session.done_views
    if len(views) < 2:
        raise ConfigError(f"{out}: {len(views)} completed view(s); processing needs at least 2 (resume the scan)")
    unverified = verify_views(session)
    if unverified:
        call_progress(progress, f"{', '.join(unverified)}: no frame checksums in session.json (written by an older "
                                "rangekit); their frames are not verified")
    # The outputs are a set: summary.json goes first and comes back last, after all the others.
    stale = out / "summary.json"
    if stale.exists():
        stale.unlink()
        fsync_folder(out)
    if session.is_laser:
        from rangekit.app.laser.process import process_laser

        return process_laser(out, session, fusion=fusion, table_margin=table_margin, evaluate=evaluate, report=report,
                             progress=progress)
    rig, spec, full_scale = session.rig, session.pattern, session.capture.full_scale
    T_table_world = table_transform(rig)
    settings = cache_settings(session, method, table_margin)
    timer = StageTimer()

    with timer.stage("decode"), reuse_freed_memory():   # each view's stacks reuse the last one's pages
        clouds: list[PointCloud] = []
        maps: list[ViewMaps] = []
        # the next view's frames are read while this one decodes (view_clouds)
        decoded = view_clouds(views, spec, rig, settings, full_scale, T_table_world, table_margin)
        for k, (cloud, view_maps) in enumerate(decoded):
            v = views[k]
            clouds.append(cloud)
            maps.append(view_maps)
            call_progress(progress, f"decoded {v.folder.name}: {len(clouds[-1]):,} points", k + 1, len(views))
        proj_cols = [m.proj_col for m in maps]
        if fusion != "tsdf":   # the TSDF fuses the depth maps; otherwise the report reads them back (230 MB)
            maps = None
        release_free_memory()   # the image stacks and decoding temporaries (rangekit._runtime.memory)

    view_passes = [v.scan_pass for v in views] if session.plan.passes > 1 else None
    step = max(1, sum(len(c) for c in clouds) // POISSON_POINTS)   # Poisson's sample: every step-th merged point
    in_child = fusion == "poisson" and -(-sum(len(c) for c in clouds) // step) >= CHILD_MIN_POINTS
    child = None
    if in_child:   # Poisson's child starts now and imports what it needs on the other core while this one registers
        child = spawn_child(CHILD_IMPORTS)
        if child is not None:
            children.enter_context(child)    # ended if anything below fails
    with timer.stage("register"):
        names = [v.folder.name for v in views]
        if view_passes is not None:    # each pass from its turntable prior, the passes to each other without one
            from rangekit.app.scan.passes import register_session_passes

            res = register_session_passes(clouds, views, rig, progress=progress, map_pairs=map_pairs)
        else:
            prior = None if rig.T_world_table is None else turntable_prior(rig.T_world_table, [v.angle for v in views])
            # On the rig's turntable the views are rotations about one axis: the joint refinement keeps them so.
            res = register_views(clouds, init_T_world_view=prior, progress=progress,
                                 options=MultiViewOptions(turntable=prior is not None), map_pairs=map_pairs)
        save_poses(out / "poses.json", names, res.T_world_view,
                   world=f"frame of {views[0].folder.name} (the rig's world at its turntable angle)",
                   extra=None if view_passes is None else [{"pass": p} for p in view_passes])
        edges, k_acc = [], 0
        for e in res.edges:
            row = {"i": e.i, "j": e.j, "rmse_mm": e.rmse * 1e3, "overlap": e.overlap, "accepted": e.accepted,
                   "reason": e.reason, "rotation_residual_deg": None, "translation_residual_mm": None}
            if e.accepted and k_acc < len(res.sync.edge_rotation_error):
                row["rotation_residual_deg"] = float(np.degrees(res.sync.edge_rotation_error[k_acc]))
                row["translation_residual_mm"] = float(res.sync.edge_translation_error[k_acc] * 1e3)
                k_acc += 1
            edges.append(row)
        release_free_memory()   # the registration's k-d trees and samples

    # The evaluator's key of each view: its turntable angle, with its pass in a multi-pass scan.
    angles = [v.angle for v in views] if view_passes is None else [(v.angle, v.scan_pass) for v in views]
    views_info = {"clouds": clouds, "T_world_view": res.T_world_view, "proj_cols": proj_cols, "names": names}
    with timer.stage("fuse"):
        merged = merge_clouds(clouds, res.T_world_view)
        n_merged = len(merged)
        sample = PointCloud(merged.points[::step].copy(), merged.colours[::step].copy(), merged.normals[::step].copy())
        prepare = getattr(evaluate, "prepare", None)
        call_progress(progress, f"fusing {n_merged:,} points ({fusion})"
                                + ("; measuring the views against the true surface alongside" if prepare else ""))
        # The fusion runs beside this thread, which writes the merged cloud and evaluates what does not need
        # the mesh. Open3D's Poisson holds the GIL for its whole run, so a large one runs in a child process
        # (rangekit._runtime.child); a small one, shorter than a child's start, and the TSDF (its input is the
        # 230 MB of depth maps) on a thread.
        # One Poisson thread: Open3D's multi-threaded Poisson is not deterministic (a resumed scan must give
        # the same mesh as an uninterrupted one); the other core evaluates beside it.
        # The fusion gives its whole surface, cut here to the observed mesh, and the surface to close, closed on
        # a thread (its numpy, scipy and numba work lets the GIL go) while the observed mesh is saved and measured.
        # A second child process took as long and 0.1-0.3 GB more at the peak (docs/benchmarks.md).
        fusing = (call_beside(poisson_surfaces, sample, depth=9, n_threads=1, in_child=in_child, child=child)
                  if fusion == "poisson" else call_beside(_tsdf_surface, maps, res.T_world_view, rig, in_child=False))
        evaluation = None
        with fusing:
            save_cloud(out / "merged.ply", merged, fields={"view": view_index(clouds)})
            # Not kept beside Poisson's octree and the evaluator (2M points, 130 MB): the report remakes it.
            del merged
            if prepare is not None:
                with timer.stage("evaluate"):
                    prepare(angles, views_info)
                proj_cols.clear()   # made into the per-view errors (12 decoded maps, 63 MB): not kept beside Poisson
            forget_pixel_rays()   # the camera's rays (63 MB), used by the decoding and the per-view errors
            # What the views observed: Poisson's input points (the TSDF's: the sample), their spacing.
            rule = observed_rule(sample.points[poisson_input(sample)] if fusion == "poisson" else sample.points)
            del sample
            rows = None
            if report:   # the report's per-view part, each view's maps read back (or, for the TSDF, as held)
                with timer.stage("report"):
                    from rangekit.app.report.page import table_up
                    from rangekit.app.report.view_rows import view_rows

                    rows = view_rows(names, clouds, (lambda k: maps[k]) if maps is not None else
                                     (lambda k: reload_maps(views[k], spec, settings)), rig=rig,
                                     full_scale=session.capture.full_scale, up=table_up(rig), progress=progress)
            release_free_memory()   # what this process freed beside Poisson, before the closing and the evaluation
            full, trimmed = fusing.result()
        with call_beside(make_watertight, trimmed, in_child=False) as closing:
            del trimmed
            mesh = rule.observed_part(full)
            del full
            mesh_info = save_one(out, mesh, fusion, MESH_FILE)
            if evaluate is not None:
                with timer.stage("evaluate"):
                    call_progress(progress, "measuring the observed mesh and each view against the true surface")
                    evaluation = evaluate_observed(evaluate, mesh, angles, views=views_info)
            watertight = rule.flagged(closing.result())
        del rule
        release_free_memory()   # the fusion's and the evaluator's temporaries
        watertight_info = save_one(out, watertight, fusion, WATERTIGHT_FILE)
        call_progress(progress, f"mesh: {len(mesh.vertices):,} vertices, {len(mesh.triangles):,} triangles observed; "
                                f"closed: {watertight_info['unobserved_vertices']:,} of "
                                f"{watertight_info['vertices']:,} vertices unobserved")

    accuracy, truth, view_errors = None, None, None
    if evaluate is not None:
        with timer.stage("evaluate"):
            call_progress(progress, "measuring the closed mesh against the true surface")
            accuracy, truth, view_errors = with_closed(evaluate, evaluation, watertight, angles)

    # Stage times are wall seconds; "evaluate" includes the part done beside the fusion (inside "fuse").
    result = ProcessResult(out, names, res.T_world_view, [len(c) for c in clouds], edges, float(res.rmse),
                           mesh_info, timer.seconds, accuracy, watertight_mesh=watertight_info, view_errors=view_errors,
                           view_passes=view_passes)
    if report:
        with timer.stage("report"):
            from rangekit.app.report.page import write_report

            call_progress(progress, "writing report.html")
            release_free_memory()   # the evaluation's temporaries
            write_report(out, result, clouds=clouds, maps=None, rows=rows,
                         merged=merge_clouds(clouds, res.T_world_view), mesh=mesh, session=session, truth=truth,
                         progress=progress, watertight=watertight)
    atomic_write_json(out / "summary.json", result.to_dict())   # last: the set is complete
    return result


def _tsdf_surface(maps: list[ViewMaps], T_world_view: np.ndarray, rig: Rig) -> tuple:
    """Each view's camera-frame depth map as stored, seen by the camera at its registered pose, fused: the
    surface (session world) twice, as :func:`rangekit.surface.fusion.poisson_surfaces` gives the surface to cut
    to the observed mesh and the one to close."""
    from rangekit.surface.fusion import tsdf_fuse

    surface = tsdf_fuse([(m.depth, None, rig.camera.with_pose(compose(Tk, rig.camera.T_world_cam)))
                         for m, Tk in zip(maps, T_world_view)], watertight=False)
    return surface, surface
