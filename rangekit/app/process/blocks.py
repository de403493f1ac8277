"""The blocks fusion (issue 51, ``--fusion blocks``, ``rangekit scan``'s): the observed mesh without Poisson, from the
sparse TSDF volume a scan fills as its views come, so that after the last frame only the last view's part is left.

- :func:`blocks_volume`: the volume's one setting (:data:`BLOCKS_VOXEL_M`, :data:`BLOCKS_EXTEND_PX`).
- :func:`volume_poses`: where each view's depth map goes in it: the turntable's prior poses (world = the first view's
  frame, known as each view arrives) when the joint registration puts every view within :data:`PRIOR_AGREES_M` of
  them, else the registered poses. On the 48-frame default scan the prior-posed volume, cut and projected onto the
  points merged at the registered poses, measured 0.0067 mm RMS and 99.67% complete, as the registered-posed one
  (docs/benchmarks.md, issue 51 M6).
- :func:`blocks_surface`: the views' depth maps in index order at those poses, marching cubes in one order
  (:meth:`rangekit.surface.block_volume.BlockVolume.surface`); a scan's volume filled ahead
  (:class:`BlocksAhead`) taken where it holds exactly those views at those poses: the same bytes.
- :func:`project_observed`: the surface cut to what the points observed, its vertices projected onto the points'
  planes (no edge halving at 0.4 mm).
- :func:`poisson_closed`: the closed mesh, Poisson's of the same sample (the volume's own surface closed measured
  0.072 mm RMS against 0.017, its hole filling 4.5 s and 6.8 GB).

Units are metres; poses ``T_world_view`` (4, 4) in the session world (the first view's frame).
"""

from __future__ import annotations

import weakref

import numpy as np

from rangekit.geometry import apply_T, compose
from rangekit.rig.rig_file import Rig, turntable_prior
from rangekit.surface.mesh import TriangleMesh

__all__ = ["BLOCKS_VOXEL_M", "BLOCKS_EXTEND_PX", "PRIOR_AGREES_M", "blocks_volume", "prior_pose", "volume_poses",
           "BlocksAhead", "FILL_IMPORTS", "fill_volume", "blocks_surface", "project_observed", "poisson_closed"]

#: The volume's voxel (metres) and each view's depth carried past its rim (pixels): 0.6 mm lost the thin object's
#: walls (95.2% complete), 0 px the strips every view's data stops short of (99.41% against 99.67% on the default
#: scan); docs/benchmarks.md, issue 51 "The streamed mesh".
BLOCKS_VOXEL_M, BLOCKS_EXTEND_PX = 0.0004, 4
#: The most a view's points may move between its turntable prior pose and its registered pose (metres, at its
#: points' box's corners) for the volume to be filled at the prior: a quarter voxel (the default scan: 0.003 mm).
PRIOR_AGREES_M = BLOCKS_VOXEL_M / 4


def blocks_volume():
    """An empty volume of the blocks fusion: the one place of its settings."""
    from rangekit.surface.block_volume import BlockVolume

    return BlockVolume(BLOCKS_VOXEL_M, extend_px=BLOCKS_EXTEND_PX)


def prior_pose(rig: Rig, angle0: float, angle: float) -> np.ndarray:
    """(4, 4) the turntable prior pose of a view at ``angle`` (radians) in the frame of the first view (at
    ``angle0``): :func:`rangekit.rig.rig_file.turntable_prior`, one view at a time (the same numbers as all at
    once)."""
    return turntable_prior(rig.T_world_table, [angle0, angle])[1]


def _prior_usable(rig: Rig, passes: int) -> bool:
    return passes == 1 and rig.T_world_table is not None


def volume_poses(rig: Rig, views, passes: int, T_world_view: np.ndarray, clouds) -> tuple[np.ndarray, bool]:
    """``(poses (n, 4, 4), prior)``: where the volume takes each of ``views`` (the session's completed views, their
    ``angle``; ``clouds`` their points, each in its own view's frame): the turntable's prior poses when the scan is
    one turntable pass and every view's points' box moves at most :data:`PRIOR_AGREES_M` between its prior and its
    registered pose ``T_world_view``, else the registered poses (``prior`` False)."""
    if not _prior_usable(rig, passes):
        return np.asarray(T_world_view), False
    prior = np.stack([prior_pose(rig, views[0].angle, v.angle) for v in views])
    for T, P, cloud in zip(T_world_view, prior, clouds):
        if len(cloud.points) == 0:
            continue
        lo, hi = cloud.points.min(axis=0), cloud.points.max(axis=0)
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        if np.max(np.linalg.norm(apply_T(T, corners) - apply_T(P, corners), axis=1)) > PRIOR_AGREES_M:
            return np.asarray(T_world_view), False
    return prior, True


class BlocksAhead:
    """A scan's blocks volume filled as its views come (:mod:`rangekit.app.scan.streaming`): each view, in index
    order from view 0, at its turntable prior pose (:func:`prior_pose`); a view out of order (one taken again after
    the object moved) ends the filling, and the processing then fills its own. :meth:`finish` integrates the last
    views and makes the surface (a scan calls it once its preview is written, on the preview's thread, beside the
    registration); :meth:`surface_of` gives that surface where it is exactly the one :func:`blocks_surface` would
    make. No thread of its own: the runner's placements run it.

    The volume lives in a child process started at view 0 (:func:`rangekit._runtime.child.spawn_child`; each view's
    depth and camera sent to it, :func:`fill_volume`): Open3D holds the GIL through the integration and the marching
    cubes, which in this process left the joint registration beside them a 20% share of the interpreter (issue 51
    M7). In a daemonic process (a Dask worker) it is filled here, as :func:`blocks_surface` fills its own: the same
    bytes either way."""

    def __init__(self, rig: Rig, angle0: float) -> None:
        from rangekit._runtime.child import spawn_child

        self._rig, self._angle0 = rig, float(angle0)
        self._child = spawn_child(FILL_IMPORTS)
        if self._child is not None:
            self._child.start(fill_volume, more=True)
            weakref.finalize(self, self._child.terminate)   # a scan that never finishes it leaves no process
            self._volume = None
        else:
            self._volume = blocks_volume()
        self.views: list[int] = []     # the view indices integrated, in order
        self.broken = False            # a view came out of order (or the surface failed): nothing here is taken
        self._surface: TriangleMesh | None = None
        self.taken = False             # the processing took the surface made here

    def add(self, k: int, depth: np.ndarray, angle: float) -> None:
        """Integrate view ``k`` (its (H, W) camera-frame depth in metres, its turntable ``angle`` in radians) if it
        is the next in index order; else stop filling (:attr:`broken`)."""
        if self.broken or k != len(self.views) or (self._volume is None and self._child is None):
            self._stop()
            return
        rig = self._rig
        camera = rig.camera.with_pose(compose(prior_pose(rig, self._angle0, angle), rig.camera.T_world_cam))
        if self._child is not None:
            self._child.send((depth, camera))
        else:
            self._volume.integrate(depth, camera)
        self.views.append(k)

    def send_now(self, k: int, depth: np.ndarray, angle: float) -> bool:
        """A last view (one :meth:`finish` would integrate), given as soon as it is decoded: sent to the volume's
        child now (True: it integrates beside the preview; pickled and queued here, a few milliseconds), or left to
        :meth:`finish` (False: a volume in this process would hold the GIL before the preview)."""
        if self._child is None:
            return False
        self.add(k, depth, angle)
        return True

    def _stop(self) -> None:
        self.broken = True
        if self._child is not None:
            self._child.terminate()
        self._child = self._volume = None

    def finish(self, last: list) -> None:
        """Integrate the ``last`` views (``(k, depth, angle)`` each), then make the surface (marching cubes in one
        order) and let the volume go; an error leaves the surface to the processing (:attr:`broken`). With the
        volume in its child, this thread waits for the child's answer without the GIL."""
        try:
            for k, depth, angle in last:
                self.add(k, depth, angle)
            if not self.broken:
                self._surface = self._child.result() if self._child is not None else self._volume.surface()
        except Exception:   # noqa: BLE001 - the processing fills its own volume and meets the error
            self.broken = True
        if self._child is not None:
            self._child.terminate()
        self._child = self._volume = None

    def surface_of(self, indices: list[int]) -> TriangleMesh | None:
        """The surface made by :meth:`finish` when it holds exactly the views ``indices`` (in order, at their
        prior poses), else None (also before :meth:`finish`)."""
        if self.broken or self._surface is None or self.views != list(indices):
            return None
        self.taken = True
        return self._surface


#: What :class:`BlocksAhead`'s child imports while the scan's first view is decoded (Open3D: 0.6 s).
FILL_IMPORTS = ("open3d", "rangekit.surface.block_volume", "rangekit.app.process.blocks")


def fill_volume() -> TriangleMesh:
    """In :class:`BlocksAhead`'s child: a blocks volume (:func:`blocks_volume`) filled with the ``(depth, camera)``
    views the scan sends (:func:`rangekit._runtime.child.messages`), in order; its surface in one order
    (:meth:`rangekit.surface.block_volume.BlockVolume.surface`)."""
    from rangekit._runtime.child import messages

    volume = blocks_volume()
    for depth, camera in messages():
        volume.integrate(depth, camera)
    return volume.surface()


def blocks_surface(maps: list, poses: np.ndarray, rig: Rig, ahead: BlocksAhead | None = None,
                   indices: list[int] | None = None) -> tuple:
    """Each view's camera-frame depth map (``maps``, in index order) integrated at ``poses``
    (:func:`volume_poses`) into the sparse volume, then marching cubes in one order: the surface (session world)
    twice, as the TSDF fusion gives it. ``ahead``: a scan's volume filled as its views came, taken when it holds
    exactly ``indices`` (the prior poses: :func:`volume_poses`' ``prior``; the caller passes it only then)."""
    if ahead is not None:
        surface = ahead.surface_of(indices)
        if surface is not None:
            return surface, surface
    volume = blocks_volume()
    for m, Tk in zip(maps, poses):
        volume.integrate(m.depth, rig.camera.with_pose(compose(Tk, rig.camera.T_world_cam)))
    surface = volume.surface()
    return surface, surface


def project_observed(full: TriangleMesh, rule, normals: np.ndarray, workers: int = 1) -> TriangleMesh:
    """``full`` cut to what the points observed (``rule``: :class:`rangekit.surface.observed.ObservedRule`, its
    :meth:`~rangekit.surface.observed.ObservedRule.observed_near` on ``workers`` threads: the same answers), its
    vertices projected onto the planes of their nearest input points (``normals`` (N, 3) in the rule's tree's order;
    :func:`rangekit.surface.refine.project_to_points`, the cut's query reused), no edge halved: at 0.4 mm voxels the
    halving changed neither RMS nor completeness on the default scan (docs/benchmarks.md)."""
    from rangekit.surface.refine import REFINE_NEIGHBOURS, project_to_points

    tree = rule.tree
    cut, d, idx = rule.observed_near(full, min(REFINE_NEIGHBOURS, tree.n), workers=workers)
    placed = project_to_points(cut.vertices, tree.data, normals, tree=tree, near=(d, idx))
    return TriangleMesh(placed, cut.triangles, cut.vertex_colours)


def poisson_closed(sample, depth: int) -> TriangleMesh:
    """The blocks fusion's closed mesh: Poisson's density-trimmed surface of ``sample`` (a PointCloud with normals;
    one thread, as the Poisson fusion's), closed (:func:`rangekit.surface.watertight.make_watertight`): the Poisson
    fusion's closed mesh. The volume's own surface closed instead measured 0.072 mm RMS against Poisson's 0.017 on the
    default scan, its hole filling (the open table side) 4.5 s and 6.8 GB."""
    from rangekit.surface.fusion import poisson_surfaces
    from rangekit.surface.watertight import make_watertight

    return make_watertight(poisson_surfaces(sample, depth=depth, n_threads=1)[1])
