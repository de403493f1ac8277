"""The decode stage: every completed view of a coded-light session, decoded, triangulated and filtered into its
cloud (:mod:`rangekit.app.process.view_cache`: or read from its cache), gathered into :class:`DecodedViews` with the
report's per-view part. The views come from the runner (:mod:`rangekit.app.runner`: decoded on its worker threads,
or ahead by the scan's live processing), in order; this stage starts no thread and announces nothing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from collections.abc import Iterable, Mapping

from rangekit.app.process.options import ProcessOptions
from rangekit.app.process.view_cache import ViewMaps, cache_settings
from rangekit.app.report.view_rows import ViewRows
from rangekit.formats.sessions.session import Session, SessionView
from rangekit.surface.cloud import PointCloud

__all__ = ["DecodedViews", "decode", "carving_table", "free_depth_of"]


@dataclass(frozen=True, eq=False)
class DecodedViews:
    """What the decode stage hands on: each completed view's cloud and what the later stages need of its maps."""

    views: list[SessionView]      # the session's completed views, in order
    clouds: list[PointCloud]      # each view's filtered cloud, session world at the view's own turntable angle
    proj_cols: list[np.ndarray]   # (H, W) float32 decoded projector columns, NaN where undecoded: the
                                  # evaluator's per-view errors; emptied by the fusion stage once used (63 MB)
    maps: list[ViewMaps] | None   # the TSDF's input (depth maps; the blocks fusion's: the depth and columns
                                  # only); None for Poisson (230 MB for 12 views not kept beside the fusion)
    settings: dict                # the cache settings the views were decoded with (view_cache.cache_settings)
    rows: ViewRows | None         # the report's per-view part, made from each view's maps as it was decoded
    free: list[np.ndarray] | None = None   # (H, W) float32 per view: camera z up to which each pixel's ray is
                                  # empty (rangekit.surface.carve.free_depth), for the closed mesh's carving;
                                  # None without a turntable

    @property
    def names(self) -> list[str]:
        return [v.folder.name for v in self.views]


def decode(session: Session, options: ProcessOptions, views: Iterable[tuple[PointCloud, ViewMaps]],
           free_ahead: Mapping[int, np.ndarray] | None = None) -> DecodedViews:
    """Gather the decoded ``views`` of ``session`` (each completed view's ``(cloud, ViewMaps)``, in order, as
    :func:`rangekit.app.process.view_cache.view_cloud` gives them) into :class:`DecodedViews`. With
    ``options.report`` each view's report row is made from its maps as it comes
    (:class:`rangekit.app.report.view_rows.ViewRowsMaker`), so no map is read back from the cache; of each view's
    maps only what the later stages need is kept (the TSDF's depth maps; Poisson's projector columns).
    ``free_ahead``: view index -> its free depth made already from the same maps (:func:`free_depth_of`; a scan's,
    as each view was decoded), taken as it is."""
    done = session.done_views
    settings = cache_settings(session, options.method, options.table_margin, options.max_motion)
    clouds: list[PointCloud] = []
    maps: list[ViewMaps] = []
    rows, view_maps = (_rows_maker(session) if options.report else None), None
    table = carving_table(session)
    free_ahead = free_ahead or {}
    free: list[np.ndarray] | None = [] if table is not None else None
    for k, (cloud, view_maps) in enumerate(views):
        clouds.append(cloud)
        if table is not None:
            index = done[k].index
            free.append(free_ahead[index] if index in free_ahead else free_depth_of(view_maps, table))
        if rows is not None:
            rows.add(done[k].folder.name, cloud, view_maps)
        maps.append(view_maps if options.fusion == "tsdf" else _column_only(view_maps, options.fusion == "blocks"))
    proj_cols = [m.proj_col for m in maps]
    kept = maps if options.fusion in ("tsdf", "blocks") else None
    del maps, view_maps
    return DecodedViews(done, clouds, proj_cols, kept, settings, None if rows is None else rows.finish(), free)


#: Decoded pixels weaker than this are not taken as seen (reconstruct_decoded's ``min_confidence``).
_MIN_CONFIDENCE = 0.03


def carving_table(session: Session):
    """What the rig's camera and projector see of the turntable top (rangekit.surface.carve.table_view); None
    without a turntable."""
    rig = session.rig
    if rig.T_world_table is None or rig.projector is None:
        return None
    from rangekit.surface.carve import table_view

    return table_view(rig.camera, rig.projector, rig.T_world_table)


def free_depth_of(m: ViewMaps, table) -> np.ndarray:
    """A view's free depth (rangekit.surface.carve.free_depth) from its maps: its kept points' depth, the table
    top's where a confident decoded column is the table's own."""
    from rangekit.surface.carve import free_depth, view_depth

    cols = np.where(m.confidence >= _MIN_CONFIDENCE, m.proj_col, np.nan)
    return free_depth(view_depth(m.depth, cols, table))


def _rows_maker(session: Session):
    from rangekit.app.report.context import table_up
    from rangekit.app.report.view_rows import ViewRowsMaker

    return ViewRowsMaker(rig=session.rig, full_scale=session.capture.full_scale, up=table_up(session.rig))


def _column_only(m: ViewMaps, depth: bool = False) -> ViewMaps:
    """What Poisson's later stages keep of a view's maps: its projector columns (the evaluator's per-view
    errors), and with ``depth`` its depth map (the blocks fusion's input); the rest is freed as the next view
    decodes."""
    return ViewMaps(m.proj_col, None, m.depth if depth else None, None, None)
