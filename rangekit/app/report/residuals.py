"""The report's histogram of the point-to-mesh residuals: how far the merged cloud's points lie from the
observed mesh fused from them (no truth needed). A wide or long-tailed histogram shows noise, outliers or
views that do not agree; drawn as an SVG (in a ``data:`` URI) with its percentiles.
"""

from __future__ import annotations

import base64

import numpy as np

__all__ = ["RESIDUAL_POINTS", "residual_histogram_svg", "residual_section"]

#: The residuals are measured on at most this many of the merged points (evenly taken).
RESIDUAL_POINTS = 200_000


def residual_histogram_svg(residuals: np.ndarray, *, bins: int = 40, size: tuple[int, int] = (520, 240)) -> str:
    """``data:image/svg+xml`` URI of the histogram of ``residuals`` (metres, finite, >= 0) from 0 to their 99.5th
    percentile (the rest counted in the last bar), axis in micrometres, share of the points per bar."""
    r = np.asarray(residuals, dtype=np.float64)
    top = float(np.percentile(r, 99.5)) if r.size else 1e-6
    top = top if top > 0 else 1e-6
    counts, _ = np.histogram(np.minimum(r, top), bins=bins, range=(0.0, top))
    share = counts / max(1, r.size)
    w, h = size
    x0, y0, pw, ph = 50, 12, w - 62, h - 52
    hi = float(share.max()) or 1.0
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" viewBox="0 0 {w} {h}" '
             'font-family="sans-serif" font-size="11">', f'<rect width="{w}" height="{h}" fill="white"/>']
    bw = pw / bins
    for k, s in enumerate(share):
        bh = ph * s / hi
        parts.append(f'<rect x="{x0 + k * bw:.1f}" y="{y0 + ph - bh:.1f}" width="{max(bw - 1, 0.5):.1f}" '
                     f'height="{bh:.1f}" fill="#1f4e79"/>')
    parts.append(f'<line x1="{x0}" y1="{y0 + ph}" x2="{x0 + pw}" y2="{y0 + ph}" stroke="#333"/>'
                 f'<line x1="{x0}" y1="{y0}" x2="{x0}" y2="{y0 + ph}" stroke="#333"/>')
    for t in np.linspace(0.0, 1.0, 5):
        x = x0 + t * pw
        parts.append(f'<text x="{x:.1f}" y="{y0 + ph + 14}" text-anchor="middle">{t * top * 1e6:.0f}</text>')
    parts.append(f'<text x="{x0 - 4}" y="{y0 + 8}" text-anchor="end">{hi:.0%}</text>'
                 f'<text x="{x0 - 4}" y="{y0 + ph}" text-anchor="end">0</text>'
                 f'<text x="{x0 + pw / 2:.1f}" y="{h - 8}" text-anchor="middle">distance from a merged point to the '
                 'observed mesh, um (share of the points per bar)</text></svg>')
    return "data:image/svg+xml;base64," + base64.b64encode("".join(parts).encode()).decode()


def residual_section(points: np.ndarray, mesh) -> list[str]:
    """HTML of the histogram of the distances from ``points`` ((N, 3) merged cloud, metres, session world) to
    ``mesh`` (the observed mesh), with their median, 95th percentile and RMS."""
    from rangekit.app.report.figures import figure
    from rangekit.surface.mesh import distance_to_surface

    P = np.asarray(points, dtype=np.float64)
    P = P[::max(1, len(P) // RESIDUAL_POINTS)]
    P = P[np.isfinite(P).all(axis=1)]
    if len(P) == 0 or len(mesh.triangles) == 0:
        return []
    r = distance_to_surface(P, mesh)
    med, p95 = np.percentile(r, [50, 95])
    rms = float(np.sqrt(np.mean(r ** 2)))
    return ["<h2>Point-to-mesh residuals (no truth needed)</h2>",
            f"<p>Distance from each merged point ({len(P):,} of them, evenly taken) to the observed mesh: median "
            f"{med * 1e3:.4f} mm, 95th percentile {p95 * 1e3:.4f} mm, RMS {rms * 1e3:.4f} mm.</p>",
            figure(residual_histogram_svg(r), "point-to-mesh residuals", alt="histogram of the point-to-mesh residuals")]
