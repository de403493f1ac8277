"""The report's panels, each ``panel(context) -> html`` (:class:`rangekit.app.report.context.ReportContext`), and
the lists of them a report shows, in order: :data:`PANELS` for coded light, :data:`HEAD_PANELS` the part every
report opens with (the laser report's own follow, :mod:`rangekit.app.laser.report`)."""

from __future__ import annotations

import base64
import html
import shlex
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

import numpy as np

from rangekit.app.report.context import CARVED_COLOUR, INVENTED_COLOUR, OBSERVED_COLOUR, SIDE_NAMES, SIDES, ReportContext
from rangekit.app.report.figures import crop as _crop, figure as _img
from rangekit.progress import call_progress
from rangekit.formats.sessions.files import MESH_FILE, WATERTIGHT_FILE

if TYPE_CHECKING:
    from rangekit.formats.sessions.session import Session
    from rangekit.formats.sessions.summary import Edge, ProcessResult
    from rangekit.surface.mesh import TriangleMesh

__all__ = ["PANELS", "HEAD_PANELS", "view_graph_svg", "command_line", "mesh_viewer"]


def summary_panel(ctx: ReportContext) -> str:
    """The title, the session and the end-of-run summary."""
    return (f"<h1>rangekit scan report</h1><p class='sub'>{html.escape(str(ctx.out.resolve()))}</p>"
            "<h2>Summary</h2>" + _summary_table(ctx.result, ctx.session))


def viewer_panel(ctx: ReportContext) -> str:
    """The interactive 3D view of the mesh, coloured by view or by the number of views that see it."""
    from rangekit.geometry import compose

    V, q = ctx.quality
    call_progress(ctx.progress, "report: 3D view")
    cameras = np.array([compose(T, ctx.session.rig.camera.T_world_cam)[:3, 3] for T in ctx.result.T_world_view])
    return "".join(mesh_viewer(ctx.mesh, V, q, cameras, up=ctx.up))


def accuracy_panel(ctx: ReportContext) -> str:
    """On the simulator: the error heat map of the mesh against the true surface, from every side."""
    from rangekit.rendering.snapshot import colour_bar, fit_camera, render_values_on_mesh
    from rangekit.surface.mesh import distance_to_surface

    a, truth, mesh = ctx.result.accuracy, ctx.truth, ctx.mesh
    if truth is None or a is None:
        return ""
    call_progress(ctx.progress, "report: error heat map")
    vmax = 1e-3 * max(0.2, round(a.p95 * 1e3 * 2, 1))
    figs = []
    for (az, el), name in zip(SIDES, SIDE_NAMES):
        cam = fit_camera(mesh.vertices, azimuth=az, elevation=el, size=ctx.size, up=ctx.up, tight=True)
        img, _ = render_values_on_mesh(mesh, cam, lambda X: distance_to_surface(X, truth), vmin=0.0,
                                       vmax=vmax, cmap="turbo", smooth=True)
        figs.append(_img(_crop(img), name, alt=f"{name}: distance to the true surface"))
    bar = colour_bar(0.0, vmax * 1e3, label="distance to the true surface, mm", cmap="turbo")
    return ("<h2>Accuracy against the true surface (simulator)</h2>"
            f"<p>RMS {a.rms * 1e3:.3f} mm, 95th percentile {a.p95 * 1e3:.3f} mm, completeness "
            f"{a.completeness:.1%} within {a.tolerance * 1e3:g} mm, on the observed mesh ({MESH_FILE}: "
            "only surface some view's points support)"
            + (f"; the closed mesh ({WATERTIGHT_FILE}): RMS {a.watertight.rms * 1e3:.3f} mm, 95th "
               f"percentile {a.watertight.p95 * 1e3:.3f} mm, "
               f"{a.watertight.unobserved_area:.0%} of its area where no view can see"
               if a.watertight is not None else "") + ".</p>"
            f"<div class='row'>{''.join(figs)}</div>" + _img(bar, "colour scale"))


def mesh_panel(ctx: ReportContext) -> str:
    """The observed mesh shaded from every side."""
    from rangekit.rendering.snapshot import fit_camera, render_mesh

    call_progress(ctx.progress, "report: mesh renders")
    mesh = ctx.mesh
    figs = [_img(_crop(render_mesh(mesh, fit_camera(mesh.vertices, azimuth=az, elevation=el, size=ctx.size, up=ctx.up,
                                                    tight=True), smooth=True, colour_by_vertex=False)), name)
            for (az, el), name in zip(SIDES, SIDE_NAMES)]
    return f"<h2>Mesh (observed surface)</h2><div class='row'>{''.join(figs)}</div>"


def closed_mesh_panel(ctx: ReportContext) -> str:
    """The closed mesh: blue where some view observed the surface, orange where it lies on the carved hull (no view
    measured it, the views saw the space around it empty), grey where the fusion guessed it."""
    from rangekit.rendering.snapshot import fit_camera, render_mesh

    watertight = ctx.watertight
    if watertight is None or watertight.observed is None:
        return ""
    call_progress(ctx.progress, "report: closed mesh renders")
    carved = watertight.carved if watertight.carved is not None else np.zeros(len(watertight.vertices), bool)
    colours = np.where(watertight.observed[:, None], np.array(OBSERVED_COLOUR),
                       np.where(carved[:, None], np.array(CARVED_COLOUR), np.array(INVENTED_COLOUR)))
    figs = [_img(_crop(render_mesh(watertight, fit_camera(watertight.vertices, azimuth=az, elevation=el, size=ctx.size,
                                                          up=ctx.up, tight=True),
                                   vertex_colours=colours, smooth=True)), name,
                 alt=f"{name}: closed mesh, orange on the carved hull, grey where guessed")
            for (az, el), name in zip(SIDES, SIDE_NAMES)]
    on_hull = float((carved & ~watertight.observed).mean())
    guessed = 1.0 - float(watertight.observed.mean()) - on_hull
    return ("<h2>Closed mesh</h2>"
            f"<p>{WATERTIGHT_FILE}: blue where some view observed the surface; orange where no view measured it "
            f"and it lies on the hull the views' free space carved ({on_hull:.1%} of its vertices, flagged "
            f"<code>carved = 1</code> in the file); grey where the fusion guessed it ({guessed:.1%}, "
            f"<code>observed = 0</code> and <code>carved = 0</code>).</p><div class='row'>{''.join(figs)}</div>")


def registration_panel(ctx: ReportContext) -> str:
    """The registered views coloured by view, from two sides, and the view graph."""
    from rangekit.app.report.viewer import swatch_legend
    from rangekit.colour import colourise
    from rangekit.rendering.snapshot import fit_camera, render_cloud

    call_progress(ctx.progress, "report: registered views")
    clouds, merged, n = ctx.clouds, ctx.merged, len(ctx.clouds)
    view_id = np.concatenate([np.full(len(c), k, dtype=np.float64) for k, c in enumerate(clouds)])
    step = max(1, len(merged) // 600_000)
    figs = [_img(_crop(render_cloud(merged.points[::step], fit_camera(ctx.mesh.vertices, azimuth=az, elevation=el,
                                                                      size=ctx.size, up=ctx.up, tight=True),
                                    values=view_id[::step], vmin=0, vmax=max(1, n - 1))), f"{name}: colour = view")
            for (az, el), name in list(zip(SIDES, SIDE_NAMES))[:2]]
    figs.append(_img(view_graph_svg(n, ctx.result.edges), "view graph"))
    return ("<h2>Registration</h2>" + f"<div class='row'>{''.join(figs)}</div>"
            + swatch_legend(colourise(np.arange(n), 0, max(1, n - 1), cmap="turbo"), [str(k) for k in range(n)],
                            title="colour = view:"))


def passes_panel(ctx: ReportContext) -> str:
    """A multi-pass scan: the cloud coloured by pass."""
    from rangekit.app.report.passes import passes_section

    return "".join(passes_section(ctx.result.view_passes, ctx.clouds, ctx.merged, ctx.mesh.vertices, ctx.up,
                                  ctx.size))


def view_errors_panel(ctx: ReportContext) -> str:
    """On the simulator: where each view's error comes from."""
    from rangekit.app.report.views import view_errors_section

    return "".join(view_errors_section(ctx.result.view_errors))


def quality_panel(ctx: ReportContext) -> str:
    """The views' agreement on the mesh (no truth needed)."""
    from rangekit.app.report.quality import quality_section

    V, q = ctx.quality
    return "".join(quality_section(ctx.mesh, V, q, up=ctx.up, sides=SIDES[:2], side_names=SIDE_NAMES[:2],
                                   size=ctx.size))


def coverage_panel(ctx: ReportContext) -> str:
    """How many views see each part of the mesh."""
    from rangekit.app.report.quality import coverage_section

    V, q = ctx.quality
    call_progress(ctx.progress, "report: coverage and residuals")
    return "".join(coverage_section(ctx.mesh, V, q, up=ctx.up, sides=SIDES[:2], side_names=SIDE_NAMES[:2],
                                    size=ctx.size))


def residuals_panel(ctx: ReportContext) -> str:
    """The histogram of the merged cloud's distances to the mesh."""
    from rangekit.app.report.residuals import residual_section

    return "".join(residual_section(ctx.merged.points, ctx.mesh))


def views_panel(ctx: ReportContext) -> str:
    """The per-view table and each view's pictures (made as the views were decoded, or here from ``maps``)."""
    rows = ctx.rows
    if rows is None:
        from rangekit.app.report.view_rows import view_rows

        rows = view_rows(ctx.result.view_names, ctx.clouds, lambda k: ctx.maps[k], rig=ctx.session.rig,
                         full_scale=ctx.session.capture.full_scale, up=ctx.up, progress=ctx.progress)
    return "".join(rows.table) + "".join(rows.views)


#: What every report opens with.
HEAD_PANELS = (summary_panel, accuracy_panel, mesh_panel, closed_mesh_panel)
#: A coded-light scan's report, in order: the one list of its panels.
PANELS = (summary_panel, viewer_panel, accuracy_panel, mesh_panel, closed_mesh_panel, registration_panel,
          passes_panel, view_errors_panel, quality_panel, coverage_panel, residuals_panel, views_panel)


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
