"""The fuse stage: the registered views merged into one cloud and fused into the observed surface (mesh.ply)
and the same surface closed (mesh_watertight.ply), the fusion running beside this thread.

Open3D's Poisson holds the GIL for its whole run, so a large one runs in a child process
(:mod:`rangekit._runtime.child`), started while the views register (:func:`poisson_child`); a small one, shorter
than a child's start, and the TSDF (its input is the 230 MB of depth maps) on a thread. One Poisson thread:
Open3D's multi-threaded Poisson is not deterministic (a resumed scan must give the same mesh as an uninterrupted
one); the other core does the work that does not need the mesh beside it (:class:`Fusion`). The fusion gives its
whole surface, cut here to the observed mesh, and the surface to close, closed on a thread (its numpy, scipy and
numba work lets the GIL go) while the observed mesh is saved and measured. A second child process took as long
and 0.1-0.3 GB more at the peak (docs/benchmarks.md).
"""

from __future__ import annotations

from contextlib import ExitStack
from dataclasses import dataclass

import numpy as np

from rangekit._runtime.child import call_beside, spawn_child
from rangekit._runtime.memory import release_free_memory
from rangekit.app.events import MeshReady, OnEvent, StageClock, emit, progress_of
from rangekit.app.process.decode import DecodedViews
from rangekit.app.process.fused_outputs import MESH_FILE, WATERTIGHT_FILE, evaluate_observed, save_one
from rangekit.app.process.options import POISSON_POINTS, ProcessOptions
from rangekit.app.process.register import RegisteredViews
from rangekit.formats.clouds import save_cloud
from rangekit.formats.sessions.session import Session
from rangekit.formats.sessions.summary import MeshFigures
from rangekit.geometry import compose
from rangekit.progress import call_progress
from rangekit.rig.rig_file import Rig
from rangekit.surface.cloud import PointCloud, merge_clouds, view_index
from rangekit.surface.mesh import TriangleMesh

__all__ = ["CHILD_MIN_POINTS", "POISSON_POINTS", "CHILD_IMPORTS", "FusedViews", "Fusion", "poisson_child"]

#: Fewest sampled points whose Poisson runs in a child process: below, it takes less than the child's start
#: (about 1 s of imports, on the other core).
CHILD_MIN_POINTS = 100_000
#: What the Poisson child imports while the views are registered (Open3D alone: 0.6 s).
CHILD_IMPORTS = ("open3d", "rangekit.surface.fusion")


@dataclass(frozen=True, eq=False)
class FusedViews:
    """The two meshes (session world, metres) as written, their summary.json entries, and the evaluator's
    answer for the observed mesh (None without an evaluator)."""

    observed: TriangleMesh       # mesh.ply
    watertight: TriangleMesh     # mesh_watertight.ply, with the per-vertex ``observed`` flag
    observed_info: MeshFigures
    watertight_info: MeshFigures
    evaluation: object | None


def _sample_step(decoded: DecodedViews, options: ProcessOptions) -> int:
    """Poisson's sample: every step-th merged point, at most ``options``' points (:data:`POISSON_POINTS` by default)."""
    return max(1, -(-sum(len(c) for c in decoded.clouds) // options.poisson(laser=False)[1]))


def poisson_child(decoded: DecodedViews, options: ProcessOptions, children: ExitStack):
    """A child process for a Poisson fusion large enough to gain from one, started now so that it imports what
    it needs on the other core while the views register (ended with ``children``); None otherwise."""
    step = _sample_step(decoded, options)
    if options.fusion != "poisson" or -(-sum(len(c) for c in decoded.clouds) // step) < CHILD_MIN_POINTS:
        return None
    child = spawn_child(CHILD_IMPORTS)
    if child is not None:
        children.enter_context(child)    # ended if anything below fails
    return child


class Fusion:
    """The fusion of ``registered`` started beside this thread; use as ``with Fusion(...) as fusion:``, do the
    work that does not need the mesh (:meth:`save_merged`, the evaluator's preparation, the report's per-view
    part), then :meth:`meshes`."""

    def __init__(self, registered: RegisteredViews, session: Session, options: ProcessOptions, child,
                 on_event: OnEvent | None = None, *, measuring_beside: bool = False) -> None:
        from rangekit.surface.fusion import poisson_surfaces

        self._registered, self._session, self._options, self._on_event = registered, session, options, on_event
        clouds, T = registered.decoded.clouds, registered.T_world_view
        merged = merge_clouds(clouds, T)
        step = _sample_step(registered.decoded, options)
        self._sample = PointCloud(merged.points[::step].copy(), merged.colours[::step].copy(),
                                  merged.normals[::step].copy())
        self._merged = merged
        self.n_merged = len(merged)
        call_progress(progress_of(on_event), f"fusing {self.n_merged:,} points ({options.fusion})"
                      + ("; measuring the views against the true surface alongside" if measuring_beside else ""))
        if options.fusion == "poisson":
            in_child = -(-self.n_merged // step) >= CHILD_MIN_POINTS
            self._call = call_beside(poisson_surfaces, self._sample, depth=options.poisson(laser=False)[0], n_threads=1,
                                     in_child=in_child, child=child)
        else:
            self._call = call_beside(_tsdf_surface, registered.decoded.maps, T, session.rig, in_child=False)

    def __enter__(self) -> "Fusion":
        self._call.__enter__()
        return self

    def __exit__(self, *exc) -> None:
        self._call.__exit__(*exc)

    def save_merged(self) -> None:
        """Write ``merged.ply`` (every view's points in the registered frame, each with its ``view``) and let the
        merged cloud go: not kept beside Poisson's octree and the evaluator (2M points, 130 MB)."""
        clouds = self._registered.decoded.clouds
        save_cloud(self._session.folder / "merged.ply", self._merged, fields={"view": view_index(clouds)})
        self._merged = None

    def meshes(self, clock: StageClock, evaluate=None, beside_observed=None) -> FusedViews:
        """Wait for the surface, cut it to the observed mesh (what Poisson's input points support) and close it
        on a thread while the observed mesh is saved and, with an evaluator, measured; then save the closed one.
        Both are announced as :class:`MeshReady`. ``beside_observed(mesh)``: called with the observed mesh once it
        is saved, to start work on it beside its evaluation (it must return at once)."""
        from rangekit.surface.observed import observed_rule
        from rangekit.surface.fusion import poisson_input
        from rangekit.surface.watertight import make_watertight

        # What the views observed: Poisson's input points (the TSDF's: the sample), their spacing.
        sample = self._sample
        rule = observed_rule(sample.points[poisson_input(sample)] if self._options.fusion == "poisson"
                             else sample.points)
        self._sample = sample = None
        release_free_memory()   # what this process freed beside Poisson, before the closing and the evaluation
        full, trimmed = self._call.result()
        out, fusion = self._session.folder, self._options.fusion
        evaluation = None
        with call_beside(make_watertight, trimmed, in_child=False) as closing:
            del trimmed
            mesh = rule.observed_part(full)
            del full
            mesh_info = save_one(out, mesh, fusion, MESH_FILE, self._options.mesh_format)
            emit(self._on_event, MeshReady("observed", out / MESH_FILE, mesh))
            if beside_observed is not None:
                beside_observed(mesh)
            if evaluate is not None:
                with clock.stage("evaluate"):
                    call_progress(progress_of(self._on_event),
                                  "measuring the observed mesh and each view against the true surface")
                    evaluation = evaluate_observed(evaluate, mesh, self._registered.angles,
                                                   views=self._registered)
            watertight = rule.flagged(closing.result())
        del rule
        release_free_memory()   # the fusion's and the evaluator's temporaries
        watertight_info = save_one(out, watertight, fusion, WATERTIGHT_FILE, self._options.mesh_format)
        emit(self._on_event, MeshReady("watertight", out / WATERTIGHT_FILE, watertight))
        call_progress(progress_of(self._on_event),
                      f"mesh: {len(mesh.vertices):,} vertices, {len(mesh.triangles):,} triangles observed; "
                      f"closed: {watertight_info.unobserved_vertices:,} of {watertight_info.vertices:,} "
                      "vertices unobserved")
        return FusedViews(mesh, watertight, mesh_info, watertight_info, evaluation)


def _tsdf_surface(maps: list, T_world_view: np.ndarray, rig: Rig) -> tuple:
    """Each view's camera-frame depth map as stored, seen by the camera at its registered pose, fused: the
    surface (session world) twice, as :func:`rangekit.surface.fusion.poisson_surfaces` gives the surface to cut
    to the observed mesh and the one to close."""
    from rangekit.surface.fusion import tsdf_fuse

    surface = tsdf_fuse([(m.depth, None, rig.camera.with_pose(compose(Tk, rig.camera.T_world_cam)))
                         for m, Tk in zip(maps, T_world_view)], watertight=False)
    return surface, surface
