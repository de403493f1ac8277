"""Processing while the scan runs (issue 36): each view decoded as soon as its frames are on disk, placed beside
the views already in, and integrated into a preview surface, while the next view is captured.

This module holds the per-view steps, with no thread of their own: :class:`StreamingViews` says which views an
event of the scan brings (:meth:`StreamingViews.views_of`) and does one view's steps when called
(:meth:`StreamingViews.view`). The job runner runs them: the STREAMING placement of the plan
(:class:`rangekit.app.runner.StreamingWorker`, issue 49) queues the views as the scan's events announce them and
calls the steps on a worker thread of lower priority that backs off while the capture is behind. One view's steps:

1. decode the view into its cache (:func:`rangekit.app.process.view_cache.view_cloud`: ``cloud.ply``,
   ``maps.npz``, ``cloud.json``, exactly what ``rangekit process`` would write), announced as
   :class:`~rangekit.app.events.ViewDecoded`: the scan's processing afterwards takes every view as it is
   (:attr:`StreamingViews.results`, the runner's memo), so its mesh is the same bytes as ``rangekit process`` of
   the session, and a view decoded once is never decoded again (an interrupted scan resumed, or processed later);
2. place it: the turntable prior refined by ICP against the view before it, at a 2 mm voxel, the refinement
   kept only within :data:`MAX_REFINE_DEG` and :data:`MAX_REFINE_M` of the prior
   (:class:`~rangekit.app.events.ViewPlaced`, the growing model for a live view); the closing refinement of all
   the views together is the processing's, once, at the end;
3. integrate its depth map into a sparse TSDF volume (:class:`rangekit.surface.block_volume.BlockVolume`, Open3D's
   ``VoxelBlockGrid``: 3-4x faster a view than the dense volume, issue 51), in one of the capture's waits
   (:mod:`rangekit.app.acquire.quiet`);
4. do ahead what the scan's processing would do with it after the last view (issue 36: the mesh within 10 s
   of the last frame), each piece taken by the processing only where it is exactly its own, so the outputs are
   the bytes ``rangekit process`` writes: the registration's levels and first-round pairs
   (:attr:`StreamingViews.registration`, :class:`rangekit.registration.ahead.RegistrationAhead`, one-pass
   turntable scans), its free depth for the closed mesh's carving (:attr:`StreamingViews.free`), and on the
   simulator the truth's samples and the view's errors against the truth
   (:attr:`StreamingViews.evaluate`); for the blocks fusion (the scan's default) its depth map integrated into the
   0.4 mm volume at its turntable prior pose (:attr:`StreamingViews.blocks`,
   :class:`rangekit.app.process.blocks.BlocksAhead`, in a child process: the last views' sent as they are decoded,
   the marching cubes waited for after the preview (:meth:`StreamingViews.finish_blocks`), beside the registration).

While the last view is taken, its frames are read as they are written (:meth:`StreamingViews.prefetch`, between
the worker's views; :mod:`rangekit.app.scan.frames_ahead`), so that after its last frame only the rest are read.
The last view (or any once the acquisition is over, :attr:`StreamingViews.acquisition_over`) is what the
preview and the processing wait for: it is decoded on every core (on the scan's thread: the runner's worker starts no
view from the last one's acquisition on), placed by the turntable prior and integrated before its cache is
written, and the scan's final view then writes ``preview.ply``, the TSDF's surface
(:meth:`StreamingViews.write_preview`, :class:`~rangekit.app.events.MeshReady` ``"preview"``; issue 51: the preview
waits for nothing but the last view's decoding); its work ahead is left to :meth:`StreamingViews.last_ahead`, run
after it; then the processing. A multi-pass scan's preview holds its first pass (the object turned over is placed
by the processing's pass registration).

A view during which the object moved (:class:`~rangekit.errors.MotionError`: the processing's check of each view,
:func:`rangekit.coded.motion.detect_motion`, ``ProcessOptions.max_motion``) is left out
(:attr:`StreamingViews.moved`) and the others go on; the scan takes such a view again once the others are in
(:func:`rangekit.app.scan.scan.scan`), and its processing checks it again.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rangekit.app.acquire.quiet import QuietWindows
from rangekit.app.events import (MeshReady, MeshStarted, OnEvent, ScanStarted, ViewAcquired, ViewDecoded, ViewPlaced,
                                 emit)
from rangekit.app.process.options import ProcessOptions
from rangekit.errors import MotionError
from rangekit.formats.sessions.session import Session
from rangekit.geometry import apply_T, compose, invert_T, rotation_angle
from rangekit.surface.cloud import PointCloud
from rangekit.formats.sessions.files import PREVIEW_FILE, partial_view_folder

__all__ = ["INTEGRATE_S", "PLACE_VOXEL_M", "MAX_REFINE_DEG", "MAX_REFINE_M", "StreamingViews"]

#: Voxel of the clouds a view is placed with (metres).
PLACE_VOXEL_M = 0.002
#: The most a view's placement may move from the turntable prior (a calibrated axis is better than a pair's ICP
#: over a small overlap, which slid 2.2 deg at 90 deg steps on the small rig): degrees, metres.
MAX_REFINE_DEG, MAX_REFINE_M = 0.5, 0.001
#: The preview's voxel: the turntable's box (its diagonal, :func:`_turntable_box`) over this many.
PREVIEW_VOXELS = 256
#: How often the frames of the last view are looked for while it is taken (seconds; :meth:`StreamingViews.prefetch`).
PREFETCH_S = 0.05
#: How long one view's TSDF integration holds the GIL (37 ms on the default rig), with a margin: it starts in a
#: wait of the capture with at least this long left (:mod:`rangekit.app.acquire.quiet`).
INTEGRATE_S = 0.06
#: The same for a view's integration into the blocks fusion's 0.4 mm volume (0.15-0.2 s loaded, issue 51).
BLOCKS_INTEGRATE_S = 0.25


class StreamingViews:
    """Decode, place and integrate each view of a coded-light scan as it comes (module doc): the steps, called
    one view at a time from one thread (the runner's :class:`rangekit.app.runner.StreamingWorker`).

    ``folder``: the session folder; ``options``: the processing's (its triangulation method and table margin make
    the cache's settings); ``on_event``: the scan's event bus (:class:`rangekit.app.bus.EventBus`), given each
    event of the steps.
    """

    def __init__(self, folder: str | Path, options: ProcessOptions, on_event: OnEvent | None = None) -> None:
        self.folder, self.options, self._on_event = Path(folder), options, on_event
        self._placed: dict[int, tuple[np.ndarray, PointCloud]] = {}
        self._volume = None
        self._preview_due = False                  # a view came into the volume since the preview was written
        self._preview_path: Path | None = None     # the preview written, if it was
        self._preview_failed: Exception | None = None   # the final view's writing of it failed (write_preview)
        self._unregistered: list = []  # the last views, their registration ahead done by last_ahead
        self._laser = False
        self.acquisition_over = False              # set once the last view is acquired: every view is urgent
        self.decoded: list[int] = []               # views decoded here, in order
        self.moved: dict = {}                      # index -> MotionError: views the object moved during
        self.results: dict = {}                    # index -> (cloud, ViewMaps): the processing takes them as they are
        self.free: dict = {}                       # index -> the view's free depth (the carving's), taken likewise
        self._table = None                         # what the camera and projector see of the table (free_depth_of)
        self.evaluate = None                       # the session's Truth, prepared view by view (NO_TRUTH on hardware)
        self.measured: list[int] = []              # views whose errors against the truth were measured here
        self.registration = None                   # RegistrationAhead of a one-pass turntable scan, from view 0 on
        self.quiet = QuietWindows()                # the capture's waits: the TSDF integration starts in one
        self._coming: int | None = None            # the last view, while it is taken (its frames read: prefetch)
        self._frames = None                        # FramesAhead: the frames of it read so far
        self.read_ahead: dict[int, int] = {}       # index -> frames of the view read while it was taken (prefetch)
        self.blocks = None                         # BlocksAhead: the blocks fusion's volume, from view 0 on
        self._blocks_last: list = []               # the last views' (k, depth, angle), integrated by finish_blocks

    def views_of(self, event) -> list[int]:
        """The views ``event`` (one of the scan's) brings to process: each view of a coded-light scan as it is
        acquired, and the done views of a resumed scan as it starts; a laser scan's steps are left to its
        processing."""
        if isinstance(event, ScanStarted):
            self._laser = event.laser          # a laser scan's profiles are placed by its own processing
            if event.resume and not event.laser:
                return [view.index for view in Session.load(self.folder).done_views]
        elif isinstance(event, ViewAcquired) and not self._laser:
            if event.index == event.total - 2:   # the last view is being taken: its frames read as they come
                self._coming = event.total - 1
            return [event.index]
        return []

    def prefetch(self) -> float | None:
        """While the scan takes its last view, between the worker's views (the runner's
        :class:`~rangekit.app.runner.StreamingWorker` calls it whenever its queue is empty): the frames of that view
        on disk so far, in frame order, read, checksummed and decoded into its stack, so that once its last frame is
        written only the rest are read (:func:`rangekit.formats.sessions.check.read_view_stack`'s ``have``: a frame
        taken again, or not the one recorded, is read again; the same pixels). One-exposure sessions. Returns how
        long to wait before calling again (None: nothing to read ahead)."""
        k = self._coming
        if k is None or k in self.decoded or k in self.moved:
            return None
        if self._frames is None or self._frames.view != k:
            from rangekit.app.scan.frames_ahead import FramesAhead

            session = Session.load(self.folder)
            if session.capture.exposures_us or k >= len(session.views):
                self._coming = None
                return None
            self._frames = FramesAhead(k, partial_view_folder(self.folder, k), len(session.pattern.frame_names))
        self._frames.read()
        return PREFETCH_S

    def view(self, k: int) -> None:
        """View ``k``'s steps (module doc; nothing if it was done already); a view the object moved during is
        recorded in :attr:`moved` and the next goes on. Any other error is raised: the runner stops the steps,
        and the processing decodes the rest itself and meets it."""
        if k in self.decoded or k in self.moved:
            return
        try:
            self._stream(k)
        except MotionError as exc:   # this view is refused; the others go on (module doc)
            self.moved[k] = exc

    def write_preview(self) -> Path | None:
        """Write and announce the preview surface, the streaming volume's (:class:`MeshStarted`, then
        :class:`MeshReady` ``"preview"``): the scan's final view does it before its cache is written, and the scan
        calls it again after the last view's steps, before its processing: written again only if a view came into
        the volume since (a resumed scan's final view, decoded first; a final view refused for motion). Its path, or
        None (no view placed); the final view's failure to write it is raised here."""
        if self._preview_failed is not None:
            error, self._preview_failed = self._preview_failed, None
            raise error
        if self._volume is None or not self._preview_due:
            return self._preview_path
        from rangekit.formats.meshes import save_mesh
        from rangekit.surface.mesh import mesh_from_open3d

        self._emit(MeshStarted("preview"))
        self._preview_due = False
        mesh = mesh_from_open3d(self._volume.mesh())
        if len(mesh.triangles) == 0:
            return None
        path = self.folder / PREVIEW_FILE
        save_mesh(path, mesh)
        self._preview_path = path
        self._emit(MeshReady("preview", path, mesh))
        return path

    def finish_blocks(self) -> None:
        """After the preview: the blocks fusion's last views integrated and its surface made
        (:meth:`rangekit.app.process.blocks.BlocksAhead.finish`); the scan runs it beside its processing, which waits
        for it (``Memo.before_mesh``) before it takes the volume."""
        if self.blocks is not None:
            self.blocks.finish(self._blocks_last)
        self._blocks_last = []

    def last_ahead(self) -> None:
        """After the last view's steps: its work ahead (module doc, 4; not its errors against the truth), which the
        processing then takes; the scan runs it after :meth:`write_preview`, so the preview waits for the last
        view's decoding only (issue 51)."""
        for k, cloud, maps, session in self._unregistered:
            try:
                self._free(k, maps, session)
            except Exception:   # noqa: BLE001 - the decode stage makes it itself and meets the error
                self.free.pop(k, None)
            self._ahead(k, cloud, maps, session, truth=False)
        self._unregistered = []

    # ------------------------------------------------------------ the steps
    def _emit(self, event) -> None:
        emit(self._on_event, event)   # the bus: thread-safe, its subscribers on its own thread

    def _stream(self, k: int) -> None:
        from rangekit.app.process.view_cache import cache_settings, table_transform, view_cloud

        session = Session.load(self.folder)
        view, rig = session.views[k], session.rig
        total = len(session.views)
        # The last view (or any once the acquisition is over) is what the preview and the processing wait for:
        # decoded on every core (the same maps: each pixel's decode is its own), into the preview (placed by the
        # turntable prior) before its cache is written, the scan's final view then writing it; its work ahead after.
        last = self.acquisition_over or k == total - 1
        previewed = []

        def preview_first(cloud: PointCloud, maps) -> None:
            self._preview(k, cloud, maps.depth, session)
            previewed.append(k)

        settings = cache_settings(session, self.options.method, self.options.table_margin, self.options.max_motion)
        have = None   # the frames read ahead (prefetch), handed on and dropped with the view's stack
        if self._frames is not None and self._frames.view == k:
            have, self._frames = self._frames.have(), None
        if have is not None:
            self.read_ahead[k] = len(have[1])
        cloud, maps = view_cloud(view, session.pattern, rig, settings, session.capture.full_scale,
                                 table_transform(rig), self.options.table_margin, session, cores=0 if last else 1,
                                 have=have, before_writes=preview_first if last else None)
        del have
        self.decoded.append(k)
        self.results[k] = (cloud, maps)
        self._emit(ViewDecoded(k, total, view.folder.name, cloud))
        self._blocks_start(k, session)
        # the acquisition ended while this view was decoded (its last view acquired: the worker hands over): the
        # preview waits for this view, so its ICP placing and its work ahead wait for the preview, as a last view's
        if last or self.acquisition_over:   # its work ahead after the preview (last_ahead), its errors after the mesh
            self._unregistered.append((k, cloud, maps, session))
            if self.blocks is not None and not self.blocks.send_now(k, maps.depth, view.angle):   # its child's: now
                self._blocks_last.append((k, maps.depth, view.angle))
            if not previewed:   # taken from its cache (a resumed scan)
                self._preview(k, cloud, maps.depth, session)
            return
        if self._placed_view(k, cloud, session):
            self._place_and_integrate(k, cloud, maps.depth, session)
        if self.blocks is not None:
            self.quiet.wait(BLOCKS_INTEGRATE_S)   # Open3D holds the GIL throughout (INTEGRATE_S)
            self.blocks.add(k, maps.depth, view.angle)
        self._free(k, maps, session)
        self._ahead(k, cloud, maps, session)

    def _blocks_start(self, k: int, session: Session) -> None:
        """At view 0 of a one-pass turntable scan fused by blocks (``--fusion blocks``, the scan's default): the
        volume that each view is integrated into as it comes (module doc, 4; the processing takes it where it is
        exactly its own, :func:`rangekit.app.process.blocks.blocks_surface`)."""
        if k == 0 and self.blocks is None and self.options.fusion == "blocks" and session.plan.passes == 1 \
                and session.rig.T_world_table is not None:
            from rangekit.app.process.blocks import BlocksAhead

            self.blocks = BlocksAhead(session.rig, session.views[0].angle)

    @staticmethod
    def _placed_view(k: int, cloud: PointCloud, session: Session) -> bool:
        """Whether view ``k`` goes into the preview: a turntable's first pass, with points."""
        return session.rig.T_world_table is not None and session.plan.view_passes()[k] == 0 and len(cloud) > 0

    def _preview(self, k: int, cloud: PointCloud, depth: np.ndarray, session: Session) -> None:
        """A last view (module doc) into the preview, placed by the turntable prior (:meth:`_place`); the scan's
        final view then writes the preview (:meth:`write_preview`; its failure is kept for the scan's own call, the
        view's steps go on)."""
        if self._placed_view(k, cloud, session):
            self._place_and_integrate(k, cloud, depth, session, refine=False)
        if k == len(session.views) - 1:
            try:
                self.write_preview()
            except Exception as exc:   # noqa: BLE001 - raised by the scan's write_preview (module doc)
                self._preview_failed = exc

    def _free(self, k: int, maps, session: Session) -> None:
        """View ``k``'s free depth, the closed mesh's carving (:func:`rangekit.app.process.decode.free_depth_of`,
        as the processing's decode stage makes it: it takes this one); nothing without a turntable."""
        from rangekit.app.process.decode import carving_table, free_depth_of

        if self._table is None:
            self._table = (carving_table(session),)
        if self._table[0] is not None:
            self.free[k] = free_depth_of(maps, self._table[0])

    def _place_and_integrate(self, k: int, cloud: PointCloud, depth: np.ndarray, session: Session, *,
                             refine: bool = True) -> None:
        T = self._place(k, cloud, session, refine=refine)
        self._emit(ViewPlaced(k, len(session.views), session.views[k].folder.name, cloud, T))
        self._integrate(depth, T, session, cloud)

    def _ahead(self, k: int, cloud: PointCloud, maps, session: Session, *, truth: bool = True) -> None:
        """What the processing would do with view ``k`` after the last view, done now (module doc, 4; ``truth``
        False: not its errors against the truth); a failure here leaves that piece to the processing, which then
        meets it itself."""
        from rangekit.app.process.register import evaluator_angles, turntable_registration
        from rangekit.app.scan.truth import session_evaluator
        from rangekit.registration.ahead import RegistrationAhead

        try:
            if self.options.truth and self.evaluate is None and k == 0:
                self.evaluate = session_evaluator(session)
            if truth and self.evaluate is not None and self.evaluate.measures:
                angles = evaluator_angles(session.views, multi_pass=session.plan.passes > 1)
                self.evaluate.prepare(angles)                  # the truth's samples, once
                self.evaluate.prepare_view(angles, k, cloud, maps.proj_col)
                self.measured.append(k)
        except Exception:   # noqa: BLE001 - the processing makes its own evaluator and meets the error
            self.evaluate = None
        if session.plan.passes != 1 or session.rig.T_world_table is None:
            return
        try:
            if k == 0 and self.registration is None:
                prior, options = turntable_registration(session.rig, session.views, cloud)
                if options.voxel is not None:
                    self.registration = RegistrationAhead(prior, options)
            if self.registration is not None and k not in self.registration.views:
                self.registration.add(k, cloud)
        except Exception:   # noqa: BLE001 - the processing registers the views itself and meets the error
            self.registration = None

    def _place(self, k: int, cloud: PointCloud, session: Session, *, refine: bool = True) -> np.ndarray:
        """View ``k``'s pose in the first view's frame: the turntable prior, refined by ICP against the nearest
        view placed before it (kept as the prior when ICP does not converge); ``refine`` False: the prior (the
        last views, placed in the preview after the acquisition: their ICP, 0.08-0.1 CPU-s, was the preview's
        largest step, and no view is placed against them; the processing registers every view, issue 51)."""
        from rangekit.registration.icp import IcpOptions, icp
        from rangekit.rig.rig_file import turntable_prior
        from rangekit.surface.cloud import downsample_with_normals

        angles = [session.views[0].angle, session.views[k].angle]
        prior = turntable_prior(session.rig.T_world_table, angles)[1]
        if not refine:
            return prior
        small = downsample_with_normals(cloud, PLACE_VOXEL_M)
        T = prior
        if self._placed:
            j = min(self._placed, key=lambda i: abs(i - k))
            T_j, target = self._placed[j]
            try:
                fit = icp(small, target, init_T_target_source=prior,
                          options=IcpOptions(max_distance=4 * PLACE_VOXEL_M, max_iterations=30))
                step = compose(fit.T_target_source, invert_T(prior))
                if fit.converged and np.degrees(rotation_angle(step[:3, :3])) <= MAX_REFINE_DEG \
                        and np.linalg.norm(step[:3, 3]) <= MAX_REFINE_M:
                    T = fit.T_target_source
            except Exception:   # noqa: BLE001 - a preview keeps the prior when a pair cannot be fitted
                T = prior
        self._placed[k] = (T, PointCloud(apply_T(T, small.points), normals=_rotated(T, small.normals)))
        return T

    def _integrate(self, depth: np.ndarray, T: np.ndarray, session: Session, cloud: PointCloud) -> None:
        from rangekit.surface.block_volume import BlockVolume

        rig = session.rig
        if self._volume is None:   # the voxel of the turntable's box / 256 (the first view's points)
            lo, hi = _turntable_box(apply_T(T, cloud.points), rig.T_world_table)
            self._volume = BlockVolume(float(np.linalg.norm(hi - lo)) / PREVIEW_VOXELS)
        camera = rig.camera.with_pose(compose(T, rig.camera.T_world_cam))
        self.quiet.wait(INTEGRATE_S)   # Open3D holds the GIL throughout: in a wait of the capture, not across a frame
        self._volume.integrate(depth, camera)
        self._preview_due = True


def _rotated(T: np.ndarray, normals: np.ndarray | None) -> np.ndarray | None:
    return None if normals is None else normals @ T[:3, :3].T


def _turntable_box(points: np.ndarray, T_world_table: np.ndarray, grow: float = 1.3) -> tuple[np.ndarray, np.ndarray]:
    """The world box holding what the turntable carries, from one view's points (world): the cylinder about the
    table's axis through the farthest of them (radius times ``grow``), between their lowest and highest along
    the axis (10% more each way)."""
    local = apply_T(invert_T(T_world_table), points)
    radius = grow * float(np.max(np.hypot(local[:, 0], local[:, 1])))
    z0, z1 = float(local[:, 2].min()), float(local[:, 2].max())
    pad = 0.1 * (z1 - z0)
    corners = np.array([[x, y, z] for x in (-radius, radius) for y in (-radius, radius) for z in (z0 - pad, z1 + pad)])
    world = apply_T(T_world_table, corners)
    return world.min(axis=0), world.max(axis=0)
