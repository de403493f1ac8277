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

import base64
import html
import shlex
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Sequence

import numpy as np

from rangekit.app.report.figures import crop as _crop, figure as _img
from rangekit.app.report.views import view_errors_section
from rangekit.io import atomic_write_text
from rangekit.progress import call_progress

if TYPE_CHECKING:
    from rangekit.app.report.view_rows import ViewRows
    from rangekit.app.process.view_cache import ViewMaps
    from rangekit.formats.sessions.session import Session
    from rangekit.formats.sessions.summary import Edge, ProcessResult
    from rangekit.surface.cloud import PointCloud
    from rangekit.surface.mesh import TriangleMesh

__all__ = ["write_report", "view_graph_svg"]

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


def view_graph_svg(n: int, edges: Sequence[Edge], *, size: int = 460) -> str:
    """The view graph as SVG: views on a circle (in turntable order), accepted pairs as lines coloured by
    their ICP RMSE (green low, red high; the label in micrometres), rejected pairs dashed grey."""
    from rangekit.colour import colourise

    c, r = size / 2, size / 2 - 40
    ang = np.pi / 2 - 2 * np.pi * np.arange(n) / n
    xy = np.column_stack([c + r * np.cos(ang), c - r * np.sin(ang)])
    acc = [e for e in edges if e.accepted]
    hi = max([e.rmse * 1e3 for e in acc], default=1.0) or 1.0
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{size}" height="{size}" '
             f'viewBox="0 0 {size} {size}" font-family="sans-serif" font-size="11">',
             f'<rect width="{size}" height="{size}" fill="white"/>']
    for e in sorted(edges, key=lambda e: e.accepted):
        (x1, y1), (x2, y2) = xy[e.i], xy[e.j]
        if e.accepted:
            rgb = colourise(np.array([e.rmse * 1e3]), 0.0, hi, cmap="turbo")[0]
            parts.append(f'<line x1="{x1:.1f}" y1="{y1:.1f}" x2="{x2:.1f}" y2="{y2:.1f}" '
                         f'stroke="rgb({rgb[0]},{rgb[1]},{rgb[2]})" stroke-width="2.5"/>')
            if abs(e.i - e.j) in (1, n - 1):
                mx, my = (x1 + x2) / 2, (y1 + y2) / 2
                parts.append(f'<text x="{mx:.1f}" y="{my:.1f}" text-anchor="middle" fill="#333">'
                             f'{e.rmse * 1e6:.0f}</text>')
        else:
            parts.append(f'<line x1="{x1:.1f}" y1="{y1:.1f}" x2="{x2:.1f}" y2="{y2:.1f}" stroke="#bbb" '
                         'stroke-width="1" stroke-dasharray="4 3"/>')
    for k, (x, y) in enumerate(xy):
        parts.append(f'<circle cx="{x:.1f}" cy="{y:.1f}" r="13" fill="#1f4e79"/>'
                     f'<text x="{x:.1f}" y="{y + 4:.1f}" text-anchor="middle" fill="white">{k}</text>')
    parts.append(f'<text x="8" y="{size - 8}" fill="#555">line colour: pair ICP RMSE, 0 (blue) to '
                 f'{hi * 1e3:.0f} um (red); labels in um; dashed: rejected</text></svg>')
    svg = "".join(parts)
    return "data:image/svg+xml;base64," + base64.b64encode(svg.encode()).decode()


def command_line(argv: Sequence[str] | None = None) -> str:
    """The command that is running, as a shell would take it (``rangekit ...`` when run as rangekit or
    ``python -m rangekit``); ``argv`` defaults to ``sys.argv``."""
    argv = list(sys.argv if argv is None else argv)
    if argv and (Path(argv[0]).name == "rangekit" or Path(argv[0]).parent.name == "rangekit"):
        argv[0] = "rangekit"
    return shlex.join(argv)


def _summary_table(result: "ProcessResult", session: "Session") -> str:
    from rangekit import __version__

    sim = session.simulator
    rows = [("session", str(result.folder)), ("written", time.strftime("%Y-%m-%d %H:%M:%S")),
            ("rangekit", __version__), ("command", command_line()),
            ("rig", "simulated" if sim else "hardware"), ("pattern", session.pattern.method)]
    if sim:
        rows += [("object", str(sim.object)), ("noise seed", str(sim.seed))]
    body = "".join(f"<tr><th>{html.escape(k)}</th><td>{html.escape(v)}</td></tr>" for k, v in rows)
    return f"<div class='tw'><table>{body}</table></div><pre>{html.escape(chr(10).join(result.summary_lines()))}</pre>"


def write_report(folder: str | Path, result: "ProcessResult", *, clouds: Sequence["PointCloud"],
                 maps: Sequence["ViewMaps"] | None, merged: "PointCloud", mesh: "TriangleMesh", session: "Session",
                 truth: "TriangleMesh | None" = None, progress: Callable | None = None,
                 size: tuple[int, int] = (230, 230), watertight: "TriangleMesh | None" = None,
                 rows: "ViewRows | None" = None) -> Path:
    """Write ``folder/report.html`` and return its path; reads nothing from disk.

    ``clouds`` are the views' clouds in their own frames and ``maps`` their decoded maps and white
    captures (as processing holds them), or None with ``rows``, the per-view part already made from them
    (:func:`rangekit.app.report.view_rows.view_rows`), ``merged`` and ``mesh`` (the observed surface) in the
    session world (the first view's frame), ``watertight`` the closed mesh there with its ``observed`` flag (shown with the
    invented part in grey), ``truth`` the true surface in that frame (from an evaluator) for the heat map.
    """
    from rangekit.colour import colourise
    from rangekit.app.report.viewer import swatch_legend
    from rangekit.rendering.snapshot import fit_camera, render_cloud

    out = Path(folder)
    rig = session.rig
    sections = head_sections(out, result, mesh=mesh, session=session, truth=truth, progress=progress, size=size,
                             watertight=watertight)
    frame_pts = mesh.vertices  # fit_camera(tight=True) frames the points themselves
    up = table_up(rig)
    sides, side_names = SIDES[:2], SIDE_NAMES[:2]
    from rangekit.app.report.quality import mesh_quality
    from rangekit.geometry import apply_T, compose

    call_progress(progress, "report: views' agreement and coverage")
    clouds_world = [apply_T(T, c.points) for T, c in zip(result.T_world_view, clouds)]
    V, q = mesh_quality(mesh.vertices, mesh.triangles, clouds_world, normal_sums=mesh.normal_sums)
    del clouds_world
    n = len(clouds)
    view_id = np.concatenate([np.full(len(c), k, dtype=np.float64) for k, c in enumerate(clouds)])
    call_progress(progress, "report: 3D view")
    cameras = np.array([compose(T, rig.camera.T_world_cam)[:3, 3] for T in result.T_world_view])   # centres
    sections[3:3] = mesh_viewer(mesh, V, q, cameras, up=up)   # after the summary

    call_progress(progress, "report: registered views")
    step = max(1, len(merged) // 600_000)
    figs = [_img(_crop(render_cloud(merged.points[::step], fit_camera(frame_pts, azimuth=az, elevation=el, size=size,
                                                                      up=up, tight=True),
                                    values=view_id[::step], vmin=0, vmax=max(1, n - 1))), f"{name}: colour = view")
            for (az, el), name in list(zip(sides, side_names))[:2]]
    figs.append(_img(view_graph_svg(n, result.edges), "view graph"))
    sections += ["<h2>Registration</h2>", f"<div class='row'>{''.join(figs)}</div>",
                 swatch_legend(colourise(np.arange(n), 0, max(1, n - 1), cmap="turbo"), [str(k) for k in range(n)],
                               title="colour = view:")]
    from rangekit.app.report.passes import passes_section

    sections += passes_section(result.view_passes, clouds, merged, frame_pts, up, size)
    sections += view_errors_section(result.view_errors)
    from rangekit.app.report.quality import coverage_section, quality_section
    from rangekit.app.report.residuals import residual_section

    sections += quality_section(mesh, V, q, up=up, sides=sides, side_names=side_names, size=size)
    call_progress(progress, "report: coverage and residuals")
    sections += coverage_section(mesh, V, q, up=up, sides=sides, side_names=side_names, size=size)
    sections += residual_section(merged.points, mesh)
    if rows is None:
        from rangekit.app.report.view_rows import view_rows

        rows = view_rows(result.view_names, clouds, lambda k: maps[k], rig=rig, full_scale=session.capture.full_scale,
                         up=up, progress=progress)
    sections += rows.table
    sections += rows.views

    return write_page(out, sections)


def mesh_viewer(mesh: "TriangleMesh", V: np.ndarray, q, cameras: np.ndarray, *, up: np.ndarray) -> list[str]:
    """The 3D view's HTML (:func:`rangekit.app.report.viewer.viewer_section`) of ``mesh`` decimated, coloured by
    view (of the views that see a vertex, the one that sees it most squarely: its camera centre, ``cameras``
    (n, 3) in the session world, closest to the vertex normal's direction) or by the number of views that see it;
    which views see a vertex comes from the quality map ``q`` on its vertices ``V`` (:func:`mesh_quality`)."""
    from scipy.spatial import cKDTree

    from rangekit.app.report.quality import count_colours
    from rangekit.app.report.viewer import decimate, swatch_legend, viewer_section
    from rangekit.colour import colourise
    from rangekit.surface.quality import vertex_normals

    Vd, Fd = decimate(mesh.vertices, mesh.triangles)
    n = len(cameras)
    near = cKDTree(V).query(Vd, k=1)[1]
    seen = np.isfinite(q.offsets[:, near]).T                                     # (Vd, n)
    to_cam = cameras[None, :, :] - Vd[:, None, :]
    facing = np.einsum("vj,vkj->vk", vertex_normals(Vd, Fd), to_cam) / np.linalg.norm(to_cam, axis=2)
    best = np.where(seen, facing, -np.inf).argmax(axis=1)
    best = np.where(seen.any(axis=1), best, facing.argmax(axis=1))             # seen by none: the facing camera
    by_view = colourise(best, 0, max(1, n - 1), cmap="turbo")                   # as the registered-views figures
    top = int(q.n_views.max()) if len(q.n_views) else 1
    by_count = count_colours(q.n_views[near], top)
    legends = [swatch_legend(colourise(np.arange(n), 0, max(1, n - 1), cmap="turbo"), [str(k) for k in range(n)],
                             title="colour = view (the one that sees the surface most squarely):", name="view"),
               swatch_legend(count_colours(np.arange(top + 1), top), [str(k) for k in range(top + 1)],
                             title="colour = number of views that see the surface:", name="views that see it")]
    return viewer_section(Vd, Fd, {"view": by_view, "views that see it": by_count}, up=up, legends=legends,
                          of=len(mesh.triangles))


#: The sides the mesh is shown from: (azimuth, elevation) radians about the turntable axis, and their names.
SIDES = [(np.radians(a), np.radians(25.0)) for a in (0, 90, 180, 270)] + [(0.0, np.radians(80.0))]
SIDE_NAMES = ["front", "right", "back", "left", "top"]


def table_up(rig) -> np.ndarray:
    """The up direction of the pictures: the turntable axis (else the camera's -y)."""
    return rig.T_world_table[:3, 2] if rig.T_world_table is not None else np.array([0.0, -1.0, 0.0])


#: The report's colours of a closed mesh: surface some view observed, and surface the fusion invented.
OBSERVED_COLOUR = (0.35, 0.62, 0.85)
INVENTED_COLOUR = (0.55, 0.55, 0.55)


def head_sections(out: Path, result: "ProcessResult", *, mesh: "TriangleMesh", session: "Session",
                  truth: "TriangleMesh | None", progress: Callable | None, size: tuple[int, int],
                  watertight: "TriangleMesh | None" = None) -> list[str]:
    """The report's title, summary, error heat map (simulator) and mesh sections, as HTML strings.

    ``mesh`` is the observed surface (heat map and shaded renders); ``watertight``, when given with its
    ``observed`` flag, is shown apart: observed surface in blue, the part no view observed in grey."""
    from rangekit.surface.mesh import distance_to_surface
    from rangekit.rendering.snapshot import colour_bar, fit_camera, render_mesh, render_values_on_mesh

    sections = [f"<h1>rangekit scan report</h1><p class='sub'>{html.escape(str(out.resolve()))}</p>",
                "<h2>Summary</h2>", _summary_table(result, session)]
    frame_pts, up, sides, side_names = mesh.vertices, table_up(session.rig), SIDES, SIDE_NAMES
    if truth is not None and result.accuracy:
        call_progress(progress, "report: error heat map")
        vmax = 1e-3 * max(0.2, round(result.accuracy.p95 * 1e3 * 2, 1))
        figs = []
        for (az, el), name in zip(sides, side_names):
            cam = fit_camera(frame_pts, azimuth=az, elevation=el, size=size, up=up, tight=True)
            img, _ = render_values_on_mesh(mesh, cam, lambda X: distance_to_surface(X, truth), vmin=0.0,
                                           vmax=vmax, cmap="turbo", smooth=True)
            figs.append(_img(_crop(img), name, alt=f"{name}: distance to the true surface"))
        bar = colour_bar(0.0, vmax * 1e3, label="distance to the true surface, mm", cmap="turbo")
        a = result.accuracy
        sections += ["<h2>Accuracy against the true surface (simulator)</h2>",
                     f"<p>RMS {a.rms * 1e3:.3f} mm, 95th percentile {a.p95 * 1e3:.3f} mm, completeness "
                     f"{a.completeness:.1%} within {a.tolerance * 1e3:g} mm, on the observed mesh (mesh.ply: "
                     "only surface some view's points support)"
                     + (f"; the closed mesh (mesh_watertight.ply): RMS {a.watertight.rms * 1e3:.3f} mm, 95th "
                        f"percentile {a.watertight.p95 * 1e3:.3f} mm, "
                        f"{a.watertight.unobserved_area:.0%} of its area where no view can see"
                        if a.watertight is not None else "") + ".</p>",
                     f"<div class='row'>{''.join(figs)}</div>", _img(bar, "colour scale")]

    call_progress(progress, "report: mesh renders")
    figs = [_img(_crop(render_mesh(mesh, fit_camera(frame_pts, azimuth=az, elevation=el, size=size, up=up, tight=True),
                                   smooth=True, colour_by_vertex=False)), name)
            for (az, el), name in zip(sides, side_names)]
    sections += ["<h2>Mesh (observed surface)</h2>", f"<div class='row'>{''.join(figs)}</div>"]
    if watertight is not None and watertight.observed is not None:
        call_progress(progress, "report: closed mesh renders")
        colours = np.where(watertight.observed[:, None], np.array(OBSERVED_COLOUR), np.array(INVENTED_COLOUR))
        figs = [_img(_crop(render_mesh(watertight, fit_camera(watertight.vertices, azimuth=az, elevation=el, size=size,
                                                              up=up, tight=True),
                                       vertex_colours=colours, smooth=True)), name,
                     alt=f"{name}: closed mesh, grey where no view observed the surface")
                for (az, el), name in zip(sides, side_names)]
        invented = 1.0 - float(watertight.observed.mean())
        sections += ["<h2>Closed mesh</h2>",
                     f"<p>mesh_watertight.ply: blue where some view observed the surface, grey where the fusion "
                     f"closed it with surface no view saw ({invented:.1%} of its vertices, flagged "
                     "<code>observed = 0</code> in the file).</p>", f"<div class='row'>{''.join(figs)}</div>"]

    return sections


def write_page(out: Path, sections: Sequence[str]) -> Path:
    """Write ``out/report.html`` (atomically) from the HTML ``sections``; returns its path."""
    page = ("<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>"
            f"<meta http-equiv='Content-Security-Policy' content=\"{CSP}\">"
            f"<title>rangekit report: {html.escape(out.name)}</title><style>{_CSS}</style></head><body>"
            + "".join(sections) + "</body></html>")
    path = out / "report.html"
    atomic_write_text(path, page)
    return path
