"""``report.html``: one self-contained page (every image and script embedded) showing what a scan did.

Sections: the summary (with the rangekit version and the command line); an interactive 3D view of the
mesh (:mod:`rangekit.app.report.viewer`: WebGL, coloured by view or by the number of views that see it);
on the simulator, the error heat map of the mesh against the true surface; the mesh shaded from several
sides; the registered views; the view graph with each pair's residual; and, with no truth needed, the
views' agreement (quality map), the coverage-count map, the histogram of the point-to-mesh residuals and
the per-view table (points, decoded share, saturation); per view its capture, decoded projector column and
confidence, depth and cloud. Every picture is a PNG in a ``data:`` URI (the view graph and histogram are
SVGs, also in ``data:`` URIs), rendered by the ray caster and z-buffer of :mod:`rangekit.rendering.snapshot`: no
display, browser or GPU is needed to write it. The page's Content-Security-Policy (``default-src 'none'``)
forbids any request: it works offline and never phones anywhere.
"""

from __future__ import annotations

import html
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Sequence

from rangekit.app.report.context import ReportContext
from rangekit.app.report.panels import PANELS
from rangekit.io import atomic_write_text
from rangekit.formats.sessions.files import REPORT_FILE

if TYPE_CHECKING:
    from rangekit.formats.sessions.view_maps import ViewMaps
    from rangekit.app.report.view_rows import ViewRows
    from rangekit.formats.sessions.session import Session
    from rangekit.formats.sessions.summary import ProcessResult
    from rangekit.surface.cloud import PointCloud
    from rangekit.surface.mesh import TriangleMesh

__all__ = ["write_report", "write_page", "CSP"]

_CSS = """
body{font-family:system-ui,-apple-system,Segoe UI,Helvetica,Arial,sans-serif;margin:24px auto;max-width:1400px;
color:#222;padding:0 16px}
h1{font-size:26px;margin-bottom:4px} h2{font-size:20px;margin-top:32px;border-bottom:1px solid #ddd}
.sub{color:#666;margin-top:0} pre{background:#f6f6f6;padding:12px;white-space:pre-wrap;font-size:13px}
.row{display:flex;flex-wrap:wrap;gap:10px;align-items:flex-start}
figure{margin:0} figcaption{font-size:12px;color:#555;text-align:center}
table{border-collapse:collapse;font-size:13px} td,th{padding:3px 6px;border-bottom:1px solid #eee;text-align:left}
img{display:block} .tw{overflow-x:auto;max-width:100%} td,th{white-space:nowrap}
.sw{display:inline-block;margin:2px 10px 2px 0;font-size:13px} .sw i{display:inline-block;width:12px;height:12px;
margin-right:4px;vertical-align:-1px;border:1px solid #999}
"""

#: The page may load nothing: images are ``data:`` URIs, styles and scripts inline.
CSP = "default-src 'none'; img-src data:; style-src 'unsafe-inline'; script-src 'unsafe-inline'"


def write_report(folder: str | Path, result: "ProcessResult", *, clouds: Sequence["PointCloud"],
                 maps: Sequence["ViewMaps"] | None, merged: "PointCloud", mesh: "TriangleMesh", session: "Session",
                 truth: "TriangleMesh | None" = None, progress: Callable | None = None,
                 size: tuple[int, int] = (230, 230), watertight: "TriangleMesh | None" = None,
                 rows: "ViewRows | None" = None, agreement: tuple | None = None,
                 map_panels: Callable = map) -> Path:
    """Write ``folder/report.html`` (every panel of :data:`rangekit.app.report.panels.PANELS`, in order) and return
    its path; reads nothing from disk.

    ``clouds`` are the views' clouds in their own frames and ``maps`` their decoded maps and white
    captures (as processing holds them), or None with ``rows``, the per-view part already made from them
    (:func:`rangekit.app.report.view_rows.view_rows`), ``merged`` and ``mesh`` (the observed surface) in the
    session world (the first view's frame), ``watertight`` the closed mesh there with its ``observed`` flag (shown
    with the invented part in grey), ``truth`` the true surface in that frame (from an evaluator) for the heat map,
    ``agreement`` the views' agreement on ``mesh`` when made already
    (:func:`rangekit.app.report.context.views_agreement`). ``map_panels(fn, panels)``: makes the panels, in order
    (the job runner's worker threads, :meth:`rangekit.app.runner.Runner.map_ordered`; by default one after
    another).
    """
    ctx = ReportContext(Path(folder), result, session, mesh, watertight=watertight, truth=truth, merged=merged,
                        clouds=clouds, rows=rows, maps=maps, size=size, progress=progress, agreement=agreement)
    # Panels side by side (map_panels), in PANELS' order on the page: each makes its own pictures; the context's
    # shared parts are cached properties (Python 3.11 computes one once under its lock; 3.12 may compute it twice,
    # the same value). The report stage 1.2-1.5 s -> 1.0-1.2 s on two cores, the same bytes (docs/benchmarks.md,
    # issue 36).
    return write_page(ctx.out, list(map_panels(lambda panel: panel(ctx), PANELS)))


def write_page(out: Path, sections: Sequence[str]) -> Path:
    """Write ``out/report.html`` (atomically) from the HTML ``sections``; returns its path."""
    page = ("<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
            f"<meta http-equiv='Content-Security-Policy' content=\"{CSP}\">"
            f"<title>rangekit report: {html.escape(out.name)}</title><style>{_CSS}</style></head><body>"
            + "".join(sections) + "</body></html>")
    path = out / REPORT_FILE
    atomic_write_text(path, page)
    return path
