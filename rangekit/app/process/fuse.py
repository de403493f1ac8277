"""The fuse stage: the registered views merged into one cloud and fused into the observed surface (mesh.ply)
and the same surface closed (mesh_watertight.ply), in steps the runner places and overlaps
(:mod:`rangekit.app.process.process`, :data:`rangekit.app.runner.PLACEMENTS`): :func:`fusion_input` (the merged
cloud and Poisson's sample), :func:`surfaces` (the fusion itself: Open3D's Poisson holds the GIL for its whole run,
so a large one runs in a child process, :data:`CHILD_MIN_POINTS`; the TSDF, whose input is the 230 MB of depth
maps, on a thread), :func:`observed_rule` (what the views observed), then the observed mesh cut and saved
(:func:`save_observed`, Poisson's surface put back on its input points, its edges halved where the surface bows
from them: :mod:`rangekit.surface.refine`) while the rest is closed (:func:`close`, on a thread: its numpy, scipy and numba work lets
the GIL go), and the closed mesh flagged and saved (:func:`save_closed`). One Poisson thread: Open3D's
multi-threaded Poisson is not deterministic (a resumed scan must give the same mesh as an uninterrupted one). A
second child process took as long and 0.1-0.3 GB more at the peak (docs/benchmarks.md).

The blocks fusion (``--fusion blocks``, issue 51: ``rangekit scan``'s) makes the observed mesh without Poisson: the
views' depth maps in index order in the sparse volume a scan streams into, its observed cut projected onto the
points' planes; its closed mesh is Poisson's of the same sample, made beside the observed mesh
(:mod:`rangekit.app.process.blocks`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.app.process.decode import DecodedViews
from rangekit.app.process.fused_outputs import save_one
from rangekit.app.process.options import POISSON_POINTS, ProcessOptions
from rangekit.app.process.register import RegisteredViews
from rangekit.formats.clouds import save_cloud
from rangekit.formats.sessions.summary import MeshFigures
from rangekit.geometry import compose
from rangekit.rig.rig_file import Rig
from rangekit.surface.cloud import PointCloud, merge_clouds, view_index
from rangekit.surface.mesh import TriangleMesh
from rangekit.formats.sessions.files import MERGED_FILE, MESH_FILE, WATERTIGHT_FILE

__all__ = ["CHILD_MIN_POINTS", "POISSON_POINTS", "CHILD_IMPORTS", "FusedViews", "FusionInput", "ObservedInput",
           "fusion_input", "large_poisson", "surfaces", "save_merged", "observed_rule", "close", "save_observed",
           "carved_space", "save_closed"]

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


@dataclass(eq=False)
class FusionInput:
    """The fusion's input: ``merged`` every view's points in the registered frame (let go once saved),
    ``sample`` Poisson's every ``step``-th point (the TSDF's too, for the observed rule; the blocks fusion's, for the
    observed rule and its closed mesh's Poisson)."""

    merged: PointCloud | None
    sample: PointCloud | None
    step: int

    @property
    def n_merged(self) -> int:
        return len(self.merged)


@dataclass(frozen=True, eq=False)
class ObservedInput:
    """What the views observed (:class:`rangekit.surface.observed.ObservedRule`, whose k-d tree holds Poisson's
    input points) and those points' (N, 3) unit normals, in the tree's order, which the observed mesh is refined
    onto (:func:`rangekit.surface.refine.refine_to_points`); ``normals`` None: a TSDF fusion, not refined."""

    rule: object
    normals: np.ndarray | None


def _sample_step(decoded: DecodedViews, options: ProcessOptions) -> int:
    """Poisson's sample: every step-th merged point, at most ``options``' points (:data:`POISSON_POINTS` by default)."""
    return max(1, -(-sum(len(c) for c in decoded.clouds) // options.poisson(laser=False)[1]))


def large_poisson(decoded: DecodedViews, options: ProcessOptions) -> bool:
    """A Poisson fusion (the blocks fusion's closed mesh's too:
    :func:`rangekit.app.process.blocks.poisson_closed`) large enough to gain from a child process (its sample at
    least :data:`CHILD_MIN_POINTS`), known once the views are decoded."""
    step = _sample_step(decoded, options)
    points = -(-sum(len(c) for c in decoded.clouds) // step)
    return options.fusion in ("poisson", "blocks") and points >= CHILD_MIN_POINTS


def fusion_input(registered: RegisteredViews, options: ProcessOptions) -> FusionInput:
    """The registered views merged (session world) and Poisson's sample of them."""
    merged = merge_clouds(registered.decoded.clouds, registered.T_world_view)
    step = _sample_step(registered.decoded, options)
    sample = PointCloud(merged.points[::step].copy(), merged.colours[::step].copy(), merged.normals[::step].copy())
    return FusionInput(merged, sample, step)


def surfaces(given: FusionInput | RegisteredViews, options: ProcessOptions, rig: Rig | None = None, *,
             passes: int = 1, ahead=None):
    """``(fn, args, kwargs)`` of the fusion, for the runner to start where it places it: Poisson of the sample
    (:func:`rangekit.surface.fusion.poisson_surfaces`, one thread), the TSDF of the registered views' depth
    maps, or the blocks volume of them (:func:`rangekit.app.process.blocks.blocks_surface`, at
    :func:`~rangekit.app.process.blocks.volume_poses` for a scan of ``passes``; ``ahead`` a scan's
    :class:`~rangekit.app.process.blocks.BlocksAhead`, taken where it is exactly its own); each gives ``(surface,
    surface to close)``, session world."""
    if options.fusion == "poisson":
        from rangekit.surface.fusion import poisson_surfaces

        return poisson_surfaces, (given.sample,), {"depth": options.poisson(laser=False)[0], "n_threads": 1}
    if options.fusion == "blocks":
        from rangekit.app.process.blocks import blocks_surface, volume_poses

        d = given.decoded
        poses, prior = volume_poses(rig, d.views, passes, given.T_world_view, d.clouds)
        return blocks_surface, (d.maps, poses, rig, ahead if prior else None, [v.index for v in d.views]), {}
    return _tsdf_surface, (given.decoded.maps, given.T_world_view, rig), {}


def save_merged(folder, fusion: FusionInput, registered: RegisteredViews) -> None:
    """Write ``merged.ply`` (every view's points in the registered frame, each with its ``view``) and let the
    merged cloud go: not kept beside Poisson's octree and the evaluator (2M points, 130 MB)."""
    clouds = registered.decoded.clouds
    save_cloud(folder / MERGED_FILE, fusion.merged, fields={"view": view_index(clouds)})
    fusion.merged = None


def observed_rule(fusion: FusionInput, options: ProcessOptions) -> ObservedInput:
    """What the views observed (:func:`rangekit.surface.observed.observed_rule`): Poisson's input points (the
    TSDF's: the sample), their spacing, and for Poisson their normals; the sample is let go."""
    from rangekit.surface.fusion import poisson_input
    from rangekit.surface.observed import observed_rule as rule_of

    sample = fusion.sample
    if options.fusion in ("poisson", "blocks"):   # (blocks: the sample is kept for the closed mesh's Poisson)
        used = poisson_input(sample)
        observed = ObservedInput(rule_of(sample.points[used]), sample.normals[used])
    else:
        observed = ObservedInput(rule_of(sample.points), None)
    if options.fusion != "blocks":
        fusion.sample = None
    return observed


def close(trimmed: TriangleMesh) -> TriangleMesh:
    """The surface to close, closed (:func:`rangekit.surface.watertight.make_watertight`)."""
    from rangekit.surface.watertight import make_watertight

    return make_watertight(trimmed)



def save_observed(folder, full: TriangleMesh, observed: ObservedInput, options: ProcessOptions,
                  workers: int = 1) -> tuple[TriangleMesh, MeshFigures]:
    """The fused surface cut to what the views observed, written as ``mesh.ply``: the mesh and its entry. Poisson's
    cut surface is put back on the input points, its edges halved where the surface bows more than
    :data:`rangekit.surface.refine.SPLIT_SAG` from them (:func:`rangekit.surface.refine.refine_to_points`, on the
    observed rule's k-d tree): at octree depth 8 its flat triangles leave curved parts (the upright bunny: 0.023 mm
    RMS, 95th percentile 0.043 mm, refined 0.013 / 0.024 with 1.6 times the vertices; docs/benchmarks.md). The
    blocks fusion's cut is projected only (:func:`rangekit.app.process.blocks.project_observed`), its query on
    ``workers`` threads (the same answers)."""
    if observed.normals is None:
        mesh = observed.rule.observed_part(full)
    elif options.fusion == "blocks":   # at 0.4 mm voxels no edge bows from the points: projected, not halved
        from rangekit.app.process.blocks import project_observed

        mesh = project_observed(full, observed.rule, observed.normals, workers=workers)
    else:   # the cut's k-d tree query gives the refinement's neighbours too
        from rangekit.surface.refine import REFINE_NEIGHBOURS, refine_to_points

        tree = observed.rule.tree
        mesh, d, idx = observed.rule.observed_near(full, min(REFINE_NEIGHBOURS, tree.n))
        mesh = refine_to_points(mesh, tree.data, observed.normals, tree=tree, near=(d, idx))
    return mesh, save_one(folder, mesh, options.fusion, MESH_FILE, options.mesh_format)


def carved_space(registered: RegisteredViews, observed: TriangleMesh, rig: Rig):
    """What the views saw as empty (:func:`rangekit.surface.carve.carve`, session world): each view's free depth
    seen from its registered camera pose, on a grid around the ``observed`` mesh (its extent and a tenth of it
    more each side, from the table top up). None without the views' free depths (no turntable). A scan of several
    passes carves with every pass's views: the rig, the table and each pixel's free depth are the same whichever
    way up the object stands, each view's registered pose puts its camera in the first pass's world, and the first
    pass's table top (the world's) is the floor. The free depths are let go once carved (63 MB for 12 views of
    1280 x 1024)."""
    from rangekit.geometry import apply_T, invert_T
    from rangekit.surface.carve import carve

    free = registered.decoded.free
    if free is None:
        return None
    views = [(f, rig.camera.with_pose(compose(Tk, rig.camera.T_world_cam)))
             for f, Tk in zip(free, registered.T_world_view)]
    P = apply_T(invert_T(rig.T_world_table), observed.vertices)
    lo, hi = P.min(axis=0), P.max(axis=0)
    pad = 0.1 * (hi - lo)
    space = carve(views, rig.T_world_table, lo - pad, hi + pad)
    free.clear()
    return space


def save_closed(folder, closed: TriangleMesh, observed: ObservedInput, options: ProcessOptions,
                space=None) -> tuple[TriangleMesh, MeshFigures]:
    """The closed surface with each vertex flagged observed or not, written as ``mesh_watertight.ply``; with
    ``space`` (:func:`carved_space`) its unobserved vertices (and the observed rim's rings around them) filled in
    where they bend least on the table top and outside carved space, then held out of it
    (:func:`rangekit.surface.carve.close_in_hull`), flagged ``carved`` where they lie on
    the hull; an observed vertex more than a voxel inside carved space is held out onto the hull too and flagged
    carved, not observed (the views saw through where the points put it)."""
    watertight = observed.rule.flagged(closed)
    if space is not None:
        from rangekit.surface.carve import close_in_hull

        V, on_hull = close_in_hull(watertight.vertices, watertight.triangles, ~watertight.observed, space)
        watertight = TriangleMesh(V, watertight.triangles, watertight.vertex_colours,
                                  watertight.observed & ~on_hull, on_hull)
    return watertight, save_one(folder, watertight, options.fusion, WATERTIGHT_FILE, options.mesh_format)


def summary_line(mesh: TriangleMesh, watertight_info: MeshFigures) -> str:
    return (f"mesh: {len(mesh.vertices):,} vertices, {len(mesh.triangles):,} triangles observed; "
            f"closed: {watertight_info.unobserved_vertices:,} of {watertight_info.vertices:,} vertices unobserved")


def _tsdf_surface(maps: list, T_world_view: np.ndarray, rig: Rig) -> tuple:
    """Each view's camera-frame depth map as stored, seen by the camera at its registered pose, fused: the
    surface (session world) twice, as :func:`rangekit.surface.fusion.poisson_surfaces` gives the surface to cut
    to the observed mesh and the one to close."""
    from rangekit.surface.fusion import tsdf_fuse

    surface = tsdf_fuse([(m.depth, None, rig.camera.with_pose(compose(Tk, rig.camera.T_world_cam)))
                         for m, Tk in zip(maps, T_world_view)], watertight=False)
    return surface, surface
