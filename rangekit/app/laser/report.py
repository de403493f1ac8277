"""``report.html`` of a laser-line scan (:data:`LASER_PANELS`): the summary, heat map and mesh of every report
(:data:`rangekit.app.report.panels.HEAD_PANELS`), then the profiles: the merged cloud coloured by turntable
step, the points each laser gave per step (a chart: a dip is a step where the line missed or was
rejected), and a few steps' laser frames with their detected peaks drawn on them.
"""

from __future__ import annotations

import base64
import html
from pathlib import Path
from typing import Callable

import numpy as np

from rangekit.app.report.context import SIDE_NAMES, SIDES, ReportContext
from rangekit.app.report.page import write_page
from rangekit.app.report.panels import HEAD_PANELS
from rangekit.app.report.figures import THUMB_W, crop as _crop, figure as _img
from rangekit.progress import call_progress

__all__ = ["write_laser_report", "points_chart_svg", "LASER_PANELS"]

#: Laser colours in the chart and on the frames (RGB).
_COLOURS = ((214, 39, 40), (31, 119, 180), (44, 160, 44), (255, 127, 14))


def points_chart_svg(n_points: np.ndarray, names: list[str], *, width: int = 560, height: int = 200) -> str:
    """A line chart of ``n_points`` (n_steps, n_lasers): points per step, one line per laser, as an SVG
    ``data:`` URI."""
    n, m = n_points.shape
    top = max(1, int(n_points.max()))
    x0, y0, w, h = 44, 12, width - 56, height - 40
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" font-family="sans-serif" '
             f'font-size="11"><rect width="{width}" height="{height}" fill="white"/>',
             f'<line x1="{x0}" y1="{y0 + h}" x2="{x0 + w}" y2="{y0 + h}" stroke="#888"/>',
             f'<line x1="{x0}" y1="{y0}" x2="{x0}" y2="{y0 + h}" stroke="#888"/>',
             f'<text x="{x0 - 4}" y="{y0 + 8}" text-anchor="end">{top:,}</text>',
             f'<text x="{x0 - 4}" y="{y0 + h}" text-anchor="end">0</text>',
             f'<text x="{x0 + w / 2}" y="{height - 6}" text-anchor="middle">turntable step (0 to {n - 1})</text>']
    xs = x0 + w * np.arange(n) / max(1, n - 1)
    for i in range(m):
        ys = y0 + h * (1 - n_points[:, i] / top)
        pts = " ".join(f"{x:.1f},{y:.1f}" for x, y in zip(xs, ys))
        r, g, b = _COLOURS[i % len(_COLOURS)]
        parts.append(f'<polyline points="{pts}" fill="none" stroke="rgb({r},{g},{b})" stroke-width="1.2"/>')
        parts.append(f'<text x="{x0 + w - 4}" y="{y0 + 12 + 13 * i}" text-anchor="end" fill="rgb({r},{g},{b})">'
                     f'{html.escape(names[i])}</text>')
    parts.append("</svg>")
    return "data:image/svg+xml;base64," + base64.b64encode("".join(parts).encode()).decode()


def _frame_with_peaks(folder: Path, session, k: int, full_scale: float | None) -> np.ndarray:
    """Laser frame ``k`` of a step with its detected peaks drawn in the laser's colour, (H, W, 3) uint8."""
    import cv2

    from rangekit.laser import detect_peaks
    from rangekit.io import read_png

    on, off = read_png(folder / f"laser{k}.png"), read_png(folder / "off.png")
    laser = session.rig.lasers[k]
    saturation = full_scale or float(np.iinfo(on.dtype).max)
    peaks = detect_peaks(on, off, channel=laser.channel if on.ndim == 3 else None, saturation=saturation)
    img = on if on.ndim == 3 else np.repeat(on[:, :, None], 3, axis=2)
    img = (img.astype(np.float32) / saturation * 255).clip(0, 255).astype(np.uint8)
    img = (img * 0.6).astype(np.uint8)
    uv = np.rint(peaks.points).astype(np.int64)
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < img.shape[1]) & (uv[:, 1] >= 0) & (uv[:, 1] < img.shape[0])
    uv = uv[inside]
    dot = np.array([0, 255, 120], dtype=np.uint8)
    for dx in (-1, 0, 1):   # 3-pixel-wide marks survive the thumbnail's downscaling
        img[uv[:, 1], np.clip(uv[:, 0] + dx, 0, img.shape[1] - 1)] = dot
    return cv2.resize(img, (THUMB_W, max(1, round(img.shape[0] * THUMB_W / img.shape[1]))),
                      interpolation=cv2.INTER_AREA)


def write_laser_report(folder: str | Path, result, *, profiles, merged, mesh, session, truth=None,
                       progress: Callable | None = None, size: tuple[int, int] = (230, 230),
                       watertight=None) -> Path:
    """Write ``folder/report.html`` of a laser scan (see the module docstring); returns its path.
    ``profiles``: :class:`rangekit.app.process.laser.LaserProfiles`; ``merged`` and ``mesh`` in the session
    world (``mesh`` the observed surface, ``watertight`` the closed one with its ``observed`` flag); ``truth``
    the true surface there (simulator) for the heat map."""
    ctx = ReportContext(Path(folder), result, session, mesh, watertight=watertight, truth=truth, merged=merged,
                        profiles=profiles, size=size, progress=progress)
    return write_page(ctx.out, [panel(ctx) for panel in LASER_PANELS])


def profiles_panel(ctx: ReportContext) -> str:
    """The profiles placed by the turntable, coloured by step, and the points each laser gave per step."""
    from rangekit.rendering.snapshot import fit_camera, render_cloud

    call_progress(ctx.progress, "report: laser profiles")
    profiles = ctx.profiles
    P, step_of = profiles.cloud.points, profiles.step.astype(np.float64)
    every = max(1, len(P) // 600_000)
    n = len(profiles.names)
    figs = [_img(_crop(render_cloud(P[::every], fit_camera(ctx.mesh.vertices, azimuth=az, elevation=el, size=ctx.size,
                                                           up=ctx.up, tight=True),
                                    values=step_of[::every], vmin=0, vmax=max(1, n - 1))), f"{name}: colour = step")
            for (az, el), name in list(zip(SIDES, SIDE_NAMES))[:2]]
    names = [laser.name for laser in ctx.session.rig.lasers]
    figs.append(_img(points_chart_svg(profiles.n_points, names), "points per step and laser"))
    return f"<h2>Laser profiles</h2><div class='row'>{''.join(figs)}</div>"


#: Steps whose laser frames the report shows.
FRAMES_SHOWN = 4


def frames_panel(ctx: ReportContext) -> str:
    """:data:`FRAMES_SHOWN` steps' laser frames with their detected peaks drawn on them."""
    profiles, session = ctx.profiles, ctx.session
    n = len(profiles.names)
    names = [laser.name for laser in session.rig.lasers]
    picks = sorted(set(np.linspace(0, n - 1, min(FRAMES_SHOWN, n)).round().astype(int).tolist()))
    rows = []
    for j in picks:
        view = ctx.out / profiles.names[j]
        figs = [_img(_frame_with_peaks(view, session, k, session.capture.full_scale),
                     f"{profiles.names[j]}: {names[k]}, {int(profiles.n_points[j, k]):,} points")
                for k in range(len(names))]
        rows.append(f"<div class='row'>{''.join(figs)}</div>")
    return "<h2>Laser frames (green: detected peaks)</h2>" + "".join(rows)


#: A laser scan's report, in order: the one list of its panels.
LASER_PANELS = (*HEAD_PANELS, profiles_panel, frames_panel)
