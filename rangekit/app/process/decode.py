"""The decode stage: every completed view of a coded-light session decoded, triangulated and filtered into its
cloud (or read from its cache, :mod:`rangekit.app.process.view_cache`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit._runtime.memory import release_free_memory, reuse_freed_memory
from rangekit.app.events import OnEvent, ViewDecoded, emit, progress_of, StageClock
from rangekit.app.process.options import ProcessOptions
from rangekit.app.process.view_cache import ViewMaps, cache_settings, table_transform, view_clouds
from rangekit.app.report.view_rows import ViewRows
from rangekit.formats.sessions.session import Session, SessionView
from rangekit.progress import call_progress
from rangekit.surface.cloud import PointCloud

__all__ = ["DecodedViews", "decode"]


@dataclass(frozen=True, eq=False)
class DecodedViews:
    """What the decode stage hands on: each completed view's cloud and what the later stages need of its maps."""

    views: list[SessionView]      # the session's completed views, in order
    clouds: list[PointCloud]      # each view's filtered cloud, session world at the view's own turntable angle
    proj_cols: list[np.ndarray]   # (H, W) float32 decoded projector columns, NaN where undecoded: the
                                  # evaluator's per-view errors; emptied by the fusion stage once used (63 MB)
    maps: list[ViewMaps] | None   # the TSDF's input (depth maps); None for Poisson (230 MB for 12 views not kept
                                  # beside the fusion)
    settings: dict                # the cache settings the views were decoded with (view_cache.cache_settings)
    rows: ViewRows | None         # the report's per-view part, made from each view's maps as it was decoded

    @property
    def names(self) -> list[str]:
        return [v.folder.name for v in self.views]


def decode(session: Session, options: ProcessOptions, clock: StageClock, on_event: OnEvent | None = None, *,
           given: dict | None = None) -> DecodedViews:
    """Decode every completed view of ``session`` in order, each announced as :class:`ViewDecoded` with its
    cloud; the next view's frames are read while this one decodes, each frame once (its SHA-256 checked against
    ``session.json`` from the bytes read). With ``options.report`` each view's report row is made from its maps
    (:class:`rangekit.app.report.view_rows.ViewRowsMaker`), so no map is read back from the cache. ``given``:
    views decoded earlier in this run (index -> (cloud, ViewMaps), frames checked then), taken as they are and
    removed from it as they are used."""
    views = session.done_views
    rig, spec = session.rig, session.pattern
    settings = cache_settings(session, options.method, options.table_margin, options.max_motion)
    progress = progress_of(on_event)
    with clock.stage("decode"), reuse_freed_memory():   # each view's stacks reuse the last one's pages
        clouds: list[PointCloud] = []
        maps: list[ViewMaps] = []
        given = given if given is not None else {}
        handed = {v.index for v in views if v.index in given}
        rest = view_clouds([v for v in views if v.index not in handed], spec, rig, settings,
                           session.capture.full_scale, table_transform(rig), options.table_margin, session)
        # a view handed on is taken out of ``given`` as it is used: its maps are freed with the others'
        decoded = (given.pop(v.index) if v.index in handed else next(rest) for v in views)
        rows, view_maps = (_rows_maker(session) if options.report else None), None
        for k, (cloud, view_maps) in enumerate(decoded):
            clouds.append(cloud)
            if rows is not None:
                rows.add(views[k].folder.name, cloud, view_maps)
            maps.append(view_maps if options.fusion == "tsdf" else _column_only(view_maps))
            if views[k].index not in handed:    # a view handed on was announced when it was decoded
                emit(on_event, ViewDecoded(k, len(views), views[k].folder.name, cloud))
            call_progress(progress, f"decoded {views[k].folder.name}: {len(cloud):,} points", k + 1, len(views))
        proj_cols = [m.proj_col for m in maps]
        kept = maps if options.fusion == "tsdf" else None
        del maps, decoded, view_maps
        release_free_memory()   # the image stacks and decoding temporaries (rangekit._runtime.memory)
    return DecodedViews(views, clouds, proj_cols, kept, settings, None if rows is None else rows.finish())


def _rows_maker(session: Session):
    from rangekit.app.report.context import table_up
    from rangekit.app.report.view_rows import ViewRowsMaker

    return ViewRowsMaker(rig=session.rig, full_scale=session.capture.full_scale, up=table_up(session.rig))


def _column_only(m: ViewMaps) -> ViewMaps:
    """What Poisson's later stages keep of a view's maps: its projector columns (the evaluator's per-view
    errors); the rest is freed as the next view decodes."""
    return ViewMaps(m.proj_col, None, None, None, None)
