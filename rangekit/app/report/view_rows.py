"""The report's per-view part, made before the mesh exists: each view's table row and its row of pictures
(white capture, projector column, confidence, depth, predicted sigma, cloud).

Processing makes it as each view is decoded (:class:`ViewRowsMaker`, :mod:`rangekit.app.process.decode`), from
the maps in hand, so the report neither reads them back nor holds the 12 views' maps (about 230 MB) beside the
meshes. The sigma pictures share one colour scale, the 99th percentile over
all views (:func:`rangekit.app.report.quality.sigma_scale`): each view's finite sigma values are kept (about
0.7 MB a view) and coloured once every view has been read.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Sequence

import numpy as np

from rangekit.app.report.figures import THUMB_W, crop as _crop, figure as _img, thumb as _thumb
from rangekit.progress import call_progress

if TYPE_CHECKING:
    from rangekit.formats.sessions.view_maps import ViewMaps
    from rangekit.rig.rig_file import Rig
    from rangekit.surface.cloud import PointCloud

__all__ = ["ViewRows", "ViewRowsMaker", "view_rows"]


@dataclass(frozen=True, eq=False)
class ViewRows:
    """HTML of the report's per-view table (``table``, :func:`rangekit.app.report.views.view_table_section`)
    and of its "Views" section (``views``)."""

    table: list[str]
    views: list[str]


def view_rows(names: Sequence[str], clouds: Sequence["PointCloud"], maps: Callable[[int], "ViewMaps"], *,
              rig: "Rig", full_scale: float | None, up: np.ndarray,
              progress: Callable | None = None) -> ViewRows:
    """The per-view part of the report: ``names`` and ``clouds`` (each in its own frame) of the views,
    ``maps(k)`` view k's :class:`~rangekit.app.process.view_cache.ViewMaps` (called once per view, in order),
    ``full_scale`` the camera's largest pixel value (None: the dtype's), ``up`` the session world's up."""
    rows = ViewRowsMaker(rig=rig, full_scale=full_scale, up=up)
    for k, (name, cloud) in enumerate(zip(names, clouds)):
        rows.add(name, cloud, maps(k))
        call_progress(progress, f"report: view {k + 1}/{len(names)}", k + 1, len(names))
    return rows.finish()


class ViewRowsMaker:
    """:func:`view_rows` one view at a time, as each is decoded (:mod:`rangekit.app.process.decode`): a view's
    maps are used in :meth:`add` and not kept; only its pictures and its finite sigma values (about 0.7 MB a
    view) wait for :meth:`finish`, which colours the sigma maps on one scale."""

    def __init__(self, *, rig: "Rig", full_scale: float | None, up: np.ndarray) -> None:
        self._rig, self._full_scale, self._up = rig, full_scale, up
        self._names: list[str] = []
        self._points: list[int] = []
        self._figures: list[list[str]] = []
        self._sigmas: list = []
        self._table: list = []

    def add(self, name: str, cloud: "PointCloud", m: "ViewMaps") -> None:
        """View ``name``'s row: its cloud (own frame) and maps."""
        from rangekit.app.report.views import view_table_figures
        from rangekit.colour import colourise
        from rangekit.rendering.snapshot import fit_camera, render_cloud

        self._names.append(name)
        self._points.append(len(cloud))
        self._table.append(view_table_figures(m, self._full_scale))
        capture = m.capture
        if capture.dtype != np.uint8:
            capture = (capture / max(1, capture.max()) * 255).astype(np.uint8)
        capture = _thumb(capture)   # a grey capture is shrunk before it is made RGB: the same pixels
        capture = capture if capture.ndim == 3 else np.repeat(capture[:, :, None], 3, axis=2)
        depth = m.depth
        finite = np.isfinite(depth)
        dlo, dhi = (np.percentile(depth[finite], [1, 99]) if finite.any() else (0.0, 1.0))
        ccam = fit_camera(cloud.points, azimuth=np.radians(20),
                          elevation=np.radians(20), size=(THUMB_W * 5 // 4, THUMB_W), up=self._up, tight=True)
        conf_top = max(1e-6, float(np.nanpercentile(m.confidence, 99)))
        col = colourise(m.proj_col, 0, self._rig.projector.width - 1, cmap="turbo")
        self._figures.append([_img(capture, f"{name}: capture (white)"),
                              _img(_thumb(col), "projector column"),
                              _img(_thumb(colourise(m.confidence, 0, conf_top, cmap="grey")), "confidence"),
                              _img(_thumb(colourise(depth, dlo, dhi, cmap="viridis")),
                                   f"depth {dlo * 1e3:.0f}-{dhi * 1e3:.0f} mm"),
                              _img(_crop(render_cloud(cloud, ccam)), f"cloud: {len(cloud):,} points")])
        self._sigmas.append(_compact(m.sigma))

    def finish(self) -> ViewRows:
        """Every view's row, the sigma pictures on one colour scale."""
        from rangekit.app.report.quality import sigma_scale
        from rangekit.app.report.views import view_table_section
        from rangekit.colour import colourise

        have = [s for s in self._sigmas if s is not None]
        if have:
            smax = sigma_scale([s[2] for s in have])
            for row, s in zip(self._figures, self._sigmas):
                if s is not None:
                    row.insert(4, _img(_thumb(colourise(_expand(s), 0.0, smax, cmap="turbo")),
                                       f"predicted sigma 0-{smax * 1e3:.3f} mm"))
        rows = [f"<div class='row'>{''.join(row)}</div>" for row in self._figures]
        return ViewRows(view_table_section(self._names, self._points, self._table), ["<h2>Views</h2>", "".join(rows)])


def _compact(sigma: np.ndarray | None) -> tuple[tuple, np.ndarray, np.ndarray] | None:
    """A sigma map as (shape, flat indices of its finite pixels, their values); None without one."""
    if sigma is None:
        return None
    flat = np.asarray(sigma).ravel()
    idx = np.flatnonzero(np.isfinite(flat))
    return (np.shape(sigma), idx, flat[idx]) if idx.size else None


def _expand(compact: tuple[tuple, np.ndarray, np.ndarray]) -> np.ndarray:
    """The sigma map of :func:`_compact` again, NaN where it had no finite value."""
    shape, idx, values = compact
    out = np.full(int(np.prod(shape)), np.nan, dtype=values.dtype)
    out[idx] = values
    return out.reshape(shape)
