"""The report's per-view tables: what each view gave (always) and, on the simulator, where its error comes from.

:func:`view_table_section` (no truth needed; :func:`view_table_figures` of each view): per view, its points,
the share of the camera's pixels decoded (a projector column found), the share kept as points, and the share
of saturated pixels in the white capture (at the camera's full scale: decoding there is unreliable; lower the
exposure or the projector's brightness).

:func:`view_errors_section`, one row per view: decoding (projector pixels against the true columns), the view's cloud against the true
surface (RMS, 95th percentile, max; inside a surface and at depth edges, and the edge points' share of the
squared error) and registration (the registered pose against the true turntable pose). The figures come
from :func:`rangekit.sim.truth.view_errors.view_errors` through the session's evaluator.
"""

from __future__ import annotations

import html
from typing import Sequence

import numpy as np

from rangekit.formats.sessions.view_errors import ViewErrors

__all__ = ["saturated_fraction", "view_errors_section", "view_table_figures", "view_table_section"]


def saturated_fraction(capture: np.ndarray, full_scale: float | None) -> float:
    """Share of the pixels of ``capture`` ((H, W) or (H, W, 3)) at or above ``full_scale`` in any channel; None
    full scale: the dtype's largest value (1.0 for a float image)."""
    img = np.asarray(capture)
    if full_scale is None:
        full_scale = float(np.iinfo(img.dtype).max) if img.dtype.kind in "ui" else 1.0
    sat = img >= full_scale
    return float((sat.any(axis=2) if sat.ndim == 3 else sat).mean()) if sat.size else 0.0


def view_table_figures(maps, full_scale: float | None) -> tuple[float, float, float]:
    """One view's figures in the per-view table, from its decoded
    :class:`~rangekit.app.process.view_cache.ViewMaps` (``proj_col``, ``depth``, the white ``capture``): the shares of
    its pixels decoded and kept as points, and of its white capture saturated at ``full_scale`` (None: the
    images' dtype's largest value)."""
    return (float(np.isfinite(maps.proj_col).mean()), float(np.isfinite(maps.depth).mean()),
            saturated_fraction(maps.capture, full_scale))


def view_table_section(names: Sequence[str], n_points: Sequence[int],
                       figures: Sequence[tuple[float, float, float]]) -> list[str]:
    """HTML of the per-view table: ``names``, their clouds' point counts and each view's
    :func:`view_table_figures`."""
    head = ("<tr><th>view</th><th>points</th><th>decoded pixels</th><th>kept as points</th>"
            "<th>saturated (white frame)</th></tr>")
    rows = []
    for name, n, (decoded, kept, sat) in zip(names, n_points, figures):
        cells = (name, f"{n:,}", f"{decoded:.1%}", f"{kept:.1%}", f"{sat:.2%}")
        style = " style='color:#b00'" if sat > 0.01 else ""
        rows.append(f"<tr{style}>" + "".join(f"<td>{html.escape(c)}</td>" for c in cells) + "</tr>")
    return ["<h2>Per view (no truth needed)</h2>",
            "<p>Decoded: share of the camera's pixels with a projector column; kept: share that became points "
            "(after the table, edge and confidence filters); saturated: share of the white capture's pixels at the "
            "camera's full scale (red above 1%: lower the exposure or the projector's brightness).</p>",
            f"<div class='tw'><table>{head}{''.join(rows)}</table></div>"]


def _f(value, fmt: str) -> str:
    return "-" if value is None else format(value, fmt)


def view_errors_section(view_errors: ViewErrors | None) -> list[str]:
    """HTML sections (a heading, a note and the table), or [] without per-view figures (shown in mm and degrees)."""
    if not view_errors:
        return []
    head = ("<tr><th>view</th><th>decoding RMS px</th><th>cloud RMS mm</th><th>p95 mm</th><th>max mm</th>"
            "<th>inside RMS mm</th><th>edge RMS mm</th><th>edge points</th><th>edge share of error&#178;</th>"
            "<th>pose error deg</th><th>pose error mm</th></tr>")
    rows = []
    for v in view_errors:
        c, r = v.cloud.to_dict(), v.registration.to_dict()      # mm and degrees, as summary.json has them
        rms_px = None if v.decoding is None else v.decoding.rms_px
        rows.append("<tr>" + "".join(f"<td>{html.escape(str(x))}</td>" for x in (
            v.view, _f(rms_px, ".3f"), _f(c["rms_mm"], ".4f"), _f(c["p95_mm"], ".4f"),
            _f(c["max_mm"], ".3f"), _f(c["inside"]["rms_mm"], ".4f"), _f(c["edge"]["rms_mm"], ".4f"),
            f"{c['edge']['n']:,}", f"{c['edge_share']:.0%}", _f(r["rotation_deg"], ".4f"),
            _f(r["translation_mm"], ".4f"))) + "</tr>")
    note = ("<p>Each view's cloud against the true surface at its turntable angle; edge points are those seen "
            "within 2 pixels of a silhouette or a depth jump (mixed pixels); decoding compares the decoded "
            "projector column with the true one; the pose error is the registered pose against the true "
            "turntable pose (translation of the object's centre).</p>")
    return ["<h2>Where the error comes from (simulator)</h2>", note, f"<div class='tw'><table>{head}{''.join(rows)}</table></div>"]
