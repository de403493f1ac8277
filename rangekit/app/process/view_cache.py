"""One view of a session decoded, triangulated and filtered, with its cache in the view folder.

Writes into ``view_NNN/`` (atomically): ``cloud.ply`` (the filtered cloud, session-world frame of that
view, with each point's predicted ``sigma``), ``maps.npz`` (uncompressed: decoded projector column, confidence,
camera-frame depth, predicted sigma along the camera ray) and ``cloud.json`` (the
settings they were made with and the SHA-256 of the other two). A view whose ``cloud.json`` holds the
same settings is read back instead of decoded again, so interrupted processing gives the same mesh as an
uninterrupted run. A damaged cache (a file missing, truncated, edited or unreadable) is rebuilt.
"""

from __future__ import annotations

import zipfile
from dataclasses import replace
from collections.abc import Callable, Iterator, Sequence
from contextlib import nullcontext

import numpy as np
from rangekit._runtime.executor import ordered_map, worker_count
from rangekit._runtime.threads import numba_threads, one_blas_thread

from rangekit import __version__
from rangekit.coded.reconstruct import EDGE_MARGIN_PX, decode_view, reconstruct_decoded
from rangekit.coded.motion import MAX_MOTION_SHARE, MOTION_METHODS, detect_motion
from rangekit.coded.patterns import PatternSpec
from rangekit.errors import MotionError, RangekitError, naming
from rangekit.formats.capture import list_images, read_stack
from rangekit.formats.sessions.session import Session, SessionView, exposure_folder
from rangekit.geometry import apply_T, invert_T
from rangekit.io import atomic_save_npz, atomic_write_json, atomic_write_with, read_json, read_png
from rangekit.progress import LOGGER
from rangekit.rig.rig_file import Rig
from rangekit.formats.clouds import load_cloud
from rangekit.formats.ply_write import write_cloud_ply
from rangekit.formats.sessions.check import file_sha256, read_view_stack, verify_views
from rangekit.formats.sessions.view_maps import ViewMaps
from rangekit.surface.cloud import PointCloud
from rangekit.formats.sessions.files import CLOUD_FILE, CLOUD_INFO_FILE, MAPS_FILE

__all__ = ["ViewMaps", "ViewCaches", "cache_settings", "table_transform", "view_cloud", "view_clouds",
           "white_frame_index"]


def cache_settings(session: Session, method: str, table_margin: float,
                   max_motion: float | None = MAX_MOTION_SHARE) -> dict:
    """The settings a coded-light session's views are decoded with, as ``cloud.json`` records them: a view's
    cache is reused only when they are equal. ``method`` is the triangulation method, ``table_margin`` in
    metres (see :func:`view_cloud`), ``max_motion`` the share of a view's decoded pixels that may have moved
    during its capture (:func:`rangekit.coded.motion.detect_motion`; over it the view is refused, MotionError;
    None: not checked; recorded for the patterns it reads, a hybrid without its finest Gray bits included: its
    blocks' edges against the phase, issue 51). The one place they are built,
    for processing in one process (:mod:`rangekit.app.process.process`) and as Dask tasks
    (:mod:`rangekit.app.batch.sessions`)."""
    rig, spec, full_scale = session.rig, session.pattern, session.capture.full_scale
    settings = {"rangekit": __version__, "method": method, "table_margin": table_margin,
                "edge_margin_px": EDGE_MARGIN_PX,
                "pattern": spec.to_dict()["method"], "full_scale": full_scale,
                "projector_response": None if rig.projector_response is None else rig.projector_response.to_dict()}
    if max_motion is not None and getattr(spec, "method", None) in MOTION_METHODS:
        settings["max_motion"] = float(max_motion)
    if session.capture.exposures_us:      # multi-exposure: each exposure decoded, merged per pixel
        settings["exposures_us"] = list(session.capture.exposures_us)
    return settings


def table_transform(rig: Rig) -> np.ndarray | None:
    """``T_table_world`` (4, 4): world points to the turntable frame, z up from the table top; None without
    a turntable."""
    return invert_T(rig.T_world_table) if rig.T_world_table is not None else None


def white_frame_index(spec: PatternSpec) -> int:
    """Index of the frame lit by the white pattern (0 if the set has none)."""
    return next((i for i, name in enumerate(spec.frame_names) if name == "white"), 0)


def _read_cache(v: SessionView, settings: dict, shape: tuple[int, int]) -> tuple[PointCloud, dict] | None:
    """The view's cached cloud and maps when ``cloud.json`` holds these settings and its files are intact
    (recorded SHA-256s, arrays of the camera's ``shape``); None otherwise (the cache is rebuilt)."""
    try:
        meta = read_json(v.folder / CLOUD_INFO_FILE, what="view cache")
        if not isinstance(meta, dict) or meta.get("settings") != settings:
            return None
        sha = meta.get("sha256")
        if not isinstance(sha, dict) or any(file_sha256(v.folder / name) != sha.get(name) for name in _CACHE_FILES):
            return None
        cloud = load_cloud(v.folder / CLOUD_FILE)
        with np.load(v.folder / MAPS_FILE) as npz:
            maps = {k: np.asarray(npz[k], dtype=np.float32) for k in _MAP_NAMES}
    except (RangekitError, OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None
    if any(m.shape != shape for m in maps.values()):
        return None
    return cloud, maps


_CACHE_FILES = (CLOUD_FILE, MAPS_FILE)
_MAP_NAMES = ("proj_col", "confidence", "depth", "sigma")  # a cache without one of them is rebuilt


def view_cloud(v: SessionView, spec: PatternSpec, rig: Rig, settings: dict, full_scale: float | None,
               T_table_world: np.ndarray | None, table_margin: float,
               session: Session | None = None, *, cores: int | None = None,
               have: tuple[np.ndarray, dict] | None = None,
               before_writes: Callable[[PointCloud, ViewMaps], None] | None = None) -> tuple[PointCloud, ViewMaps]:
    """Decode, triangulate and filter one view, or reuse its cache when made with the same ``settings``, on this
    thread: with ``cores`` None its numba setting holds; else on one BLAS thread and ``cores`` numba threads
    (0: the configured number, :func:`rangekit._runtime.executor.worker_count`; the scan's live processing decodes
    a view on 1 while the capture runs, on every core once it waits for the view).

    ``settings["method"]`` is the triangulation method, ``settings["exposures_us"]`` (when present) the
    exposures of a multi-exposure session, each decoded from its ``e<us>/`` folder and merged per pixel; ``full_scale`` the camera's largest pixel value
    (None: the images' dtype). Points less than ``table_margin`` metres above the turntable top
    (``T_table_world`` maps world points to the table frame; None: no table) are dropped. ``session``: the
    frames are checked against its recorded SHA-256s (:func:`view_clouds`). ``have``: ``(stack, {frame name:
    SHA-256})``, the view's frames already read into ``stack`` (K, H, W) as far as they go (one exposure; the scan's
    last view: :meth:`rangekit.app.scan.streaming.StreamingViews.prefetch`): only the rest are read
    (:func:`rangekit.formats.sessions.check.read_view_stack`), the same pixels. ``before_writes(cloud, maps)``:
    called with the view's cloud and maps once it is decoded, before its cache is written (not for a view taken
    from its cache; the scan's last views go into its preview first, issue 51); the same bytes are written after.
    """
    if cores is not None:
        with one_blas_thread(), numba_threads(worker_count(cores)):
            return view_cloud(v, spec, rig, settings, full_scale, T_table_world, table_margin, session, have=have,
                              before_writes=before_writes)
    return next(view_clouds([v], spec, rig, settings, full_scale, T_table_world, table_margin, session, workers=1,
                            have=None if have is None else {v.index: have}, before_writes=before_writes))


def view_clouds(views: Sequence[SessionView], spec: PatternSpec, rig: Rig, settings: dict,
                full_scale: float | None, T_table_world: np.ndarray | None,
                table_margin: float, session: Session | None = None, *,
                workers: int = 0, map_views=None, have: dict | None = None,
                before_writes: Callable[[PointCloud, ViewMaps], None] | None = None
                ) -> Iterator[tuple[PointCloud, ViewMaps]]:
    """:func:`view_cloud` of each view, yielded in order, ``workers`` views at a time on as many threads
    (:func:`rangekit._runtime.executor.ordered_map`; 0: the configured number, each with one numba and one BLAS
    thread; 1: on this thread, one view after another): two views side by side used
    1.9 cores of 2 where one view with two numba threads used 1.5 (the default session's 12 views: 6.5 s instead of
    9.4). A view's error is raised when its turn comes.

    ``session``: each frame is checked against the SHA-256 recorded in its ``session.json``, taken from the bytes
    read for decoding (:func:`rangekit.formats.sessions.check.read_view_stack`: each frame read once); a view
    taken from its cache has its frames hashed there instead. None: the frames are read unchecked. ``map_views(fn,
    views)``: the job runner's map (in order, on the configured number of threads) instead of this one's. ``have``:
    view index -> frames already read, ``before_writes``: called for each view decoded, on its thread
    (:func:`view_cloud`)."""
    shape = (rig.camera.height, rig.camera.width)
    white = white_frame_index(spec)

    def one(v: SessionView) -> tuple[PointCloud, ViewMaps]:
        folders = _frame_folders(v, settings)
        cached = _read_cache(v, settings, shape)
        if cached is not None:
            if session is not None:
                verify_views(session, views=[v])
            return cached[0], _stored_maps(cached[1], folders, white)
        stacks = _read_stacks(v, folders, session, None if have is None else have.get(v.index))
        # the white capture copied out: a view of it would keep the view's whole stack alive
        white_image = stacks[0][white].copy()
        # the frames handed over in a list that _decode_view empties: no frame of this view is kept once decoded
        held = [stacks if settings.get("exposures_us") else stacks[0]]
        del stacks
        with one_blas_thread(), (numba_threads(1) if n > 1 else nullcontext()):   # thin products
            return _decode_view(v, held, white_image, spec, rig, settings, full_scale, T_table_world, table_margin,
                                before_writes)

    n = worker_count(workers)
    if map_views is not None:   # the job runner's map over views (rangekit.app.runner.Runner.map_views)
        yield from map_views(one, views)
        return
    yield from ordered_map(one, views, workers=n, name="rangekit-views")


class ViewCaches:
    """The views of a session decoded into their caches elsewhere (the Dask batch's view tasks,
    :mod:`rangekit.app.batch.sessions`), as the job runner's memo holds decoded views
    (:attr:`rangekit.app.runner.Memo.decoded`: index -> ``(cloud, ViewMaps)``, taken out with :meth:`pop`). Nothing
    is read until a view is taken: :meth:`pop` reads its cache then, its frames checked against their recorded
    SHA-256s as every cached view's are (:func:`view_cloud` with the session; a cache no longer valid is decoded
    again there), so at most the view being taken is held.

    ``folder``: the session; ``indices``: the views whose caches were written; ``method``, ``table_margin``,
    ``max_motion``: the processing's options (:func:`cache_settings`). The session is read once, at the first
    :meth:`pop` (inside the processing's lock).
    """

    def __init__(self, folder, indices, method: str, table_margin: float, max_motion: float | None) -> None:
        self.folder, self._left = folder, list(indices)
        self._options = (method, table_margin, max_motion)
        self._session: Session | None = None

    def __contains__(self, index) -> bool:
        return index in self._left

    def __len__(self) -> int:
        return len(self._left)

    def __iter__(self) -> Iterator[int]:
        return iter(list(self._left))

    def pop(self, index: int) -> tuple[PointCloud, ViewMaps]:
        """View ``index``'s cloud and maps, read from its cache (class doc); KeyError when it is not held."""
        if index not in self._left:
            raise KeyError(index)
        if self._session is None:
            self._session = Session.load(self.folder)
        session = self._session
        view = next(v for v in session.views if v.index == index)
        self._left.remove(index)
        method, table_margin, max_motion = self._options
        return view_cloud(view, session.pattern, session.rig, cache_settings(session, method, table_margin, max_motion),
                          session.capture.full_scale, table_transform(session.rig), table_margin, session)


def _stored_maps(m: dict, folders: list, white: int) -> ViewMaps:
    """:class:`ViewMaps` of the cache's arrays ``m`` (:data:`_MAP_NAMES`) and the white capture of the view's
    first frame folder (the shortest exposure's)."""
    white_file = list_images(folders[0])[white]     # 000.png or 000.npy.zst, in frame order
    return ViewMaps(m["proj_col"], m["confidence"], m["depth"], read_png(white_file), m["sigma"])


def _frame_folders(v: SessionView, settings: dict) -> list:
    """The folders of a view's stacks: the view's, or (multi-exposure) one ``e<us>/`` per exposure, the
    shortest first (its white capture is the one shown)."""
    exposures = settings.get("exposures_us")
    return [v.folder] if not exposures else [v.folder / exposure_folder(e) for e in exposures]


def _read_stacks(v: SessionView, folders: list, session: Session | None, have=None) -> list:
    """Each folder's frames as one stack, each in a fresh array freed as soon as the view is decoded: kept for a
    thread's next view (:func:`rangekit._runtime.memory.reused_array`) the decode stage's peak was 110-170 MB higher
    (1.41-1.47 GB against 1.29-1.33 GB, ``rangekit process`` of the 12-view default session, issue 51), for no CPU
    that a side-by-side measured (20.7 against 20.8 CPU-s). ``have``: the frames of a one-folder view already read (:func:`view_cloud`)."""
    if session is None:
        return [read_stack(list_images(f)) for f in folders]
    return [read_view_stack(session, v, f, have=have if len(folders) == 1 else None) for f in folders]


def _check_still(stacks, spec: PatternSpec, decoded: np.ndarray, max_motion: float) -> None:
    """MotionError when more than ``max_motion`` of the ``decoded`` pixels moved during a capture of ``stacks``
    (each exposure's; :func:`rangekit.coded.motion.detect_motion`): the maps are not changed, a still view keeps
    its bytes."""
    for stack in stacks:
        moved = detect_motion(stack, spec, decoded)
        if moved.share > max_motion:
            raise MotionError(f"the object moved during the capture: {moved.describe()}; more than {max_motion:.0%} "
                              "moved (max_motion); capture the view again")


def _decode_view(v: SessionView, held: list, white_image: np.ndarray, spec: PatternSpec, rig: Rig, settings: dict,
                 full_scale: float | None, T_table_world: np.ndarray | None,
                 table_margin: float, before_writes=None) -> tuple[PointCloud, ViewMaps]:
    """:func:`view_cloud` past its cache, on one BLAS thread: its products are thin, (N, 3) @ (3, 3), and two
    OpenBLAS threads spent 2x the CPU on them for the same bits. ``held``: a list of one item, the view's frames
    (one exposure's stack, or the list of every exposure's), taken out of it so that they are freed as soon as
    decoded and checked, not held while the view is triangulated and written (the decode stage's peak: issue 51)."""
    exposures = settings.get("exposures_us")
    stacks = held.pop()
    with naming(v.folder):      # a view refused (the object moved during it: MotionError) is named
        dec = decode_view(stacks, spec, rig.camera, rig.projector, full_scale=full_scale,
                          response=rig.projector_response, exposures_us=exposures)
        if settings.get("max_motion") is not None:
            _check_still(stacks if exposures else [stacks], spec, np.isfinite(dec.proj_col), settings["max_motion"])
    # the decoded white copied out of the stack (a view of it otherwise): the frames are freed before the
    # triangulation (a view's peak 75 MB lower at 60 frames)
    dec = replace(dec, white=np.array(dec.white))
    del stacks
    rec = reconstruct_decoded(dec, rig.camera, rig.projector, method=settings["method"], full_scale=full_scale)
    del dec
    if rec.rig_check is not None and rec.rig_check.checkable and not rec.rig_check.fits:
        # a session's rig is its own: said, not refined per view (rangekit reconstruct refines one capture's)
        LOGGER.warning(f"{v.folder}: {rec.rig_check.describe()}")
    xyz = rec.triangulated.xyz      # read only here: no (H, W, 3) float64 copy (31 MB at 1280 x 1024)
    valid = np.isfinite(xyz[:, :, 0])
    c = rec.cloud
    if T_table_world is not None:
        keep = apply_T(T_table_world, c.points)[:, 2] > table_margin
        idx = np.flatnonzero(valid.ravel())
        valid.ravel()[idx[~keep]] = False
        c = c.take(keep)
    # Normals as stored (float32), so a run from the cache and a fresh one see the same numbers.
    c = PointCloud(c.points, c.colours, c.normals.astype(np.float32), c.sigma)
    depth = np.full(valid.shape, np.nan, dtype=np.float32)
    depth[valid] = apply_T(invert_T(rig.camera.T_world_cam), xyz[valid])[:, 2]
    sigma = np.full(valid.shape, np.nan, dtype=np.float32)
    if rec.sigma is not None:
        sigma[valid] = rec.sigma[valid]
    maps = ViewMaps(rec.decoded.proj_col.astype(np.float32), rec.decoded.confidence.astype(np.float32), depth,
                    white_image, sigma)
    if before_writes is not None:   # the scan's last view into its preview first (view_cloud)
        before_writes(c, maps)
    # Each file's SHA-256 taken from the bytes as they are written: nothing is read back.
    sha256 = {CLOUD_FILE: atomic_write_with(v.folder / CLOUD_FILE, lambda f: write_cloud_ply(f, c), sha256=True),
              # uncompressed: deflating the float maps cost 0.18 CPU-s a view (21 MB instead of 4 MB on disk)
              MAPS_FILE: atomic_save_npz(v.folder / MAPS_FILE, level=0, sha256=True, proj_col=maps.proj_col,
                                          confidence=maps.confidence, depth=depth, sigma=sigma)}
    # cloud.json last, with the others' checksums: it vouches for a complete cache.
    atomic_write_json(v.folder / CLOUD_INFO_FILE, {"settings": settings, "points": len(c), "sha256": sha256})
    return c, maps
