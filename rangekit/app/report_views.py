"""The report's per-view error table (simulator): where each view's error comes from.

One row per view: decoding (projector pixels against the true columns), the view's cloud against the true
surface (RMS, 95th percentile, max; inside a surface and at depth edges, and the edge points' share of the
squared error) and registration (the registered pose against the true turntable pose). The figures come
from :func:`rangekit.sim.view_errors.view_errors` through the session's evaluator.
"""

from __future__ import annotations

import html

__all__ = ["view_errors_section"]


def _f(value, fmt: str) -> str:
    return "-" if value is None else format(value, fmt)


def view_errors_section(view_errors: list[dict] | None) -> list[str]:
    """HTML sections (a heading, a note and the table), or [] without per-view figures."""
    if not view_errors:
        return []
    head = ("<tr><th>view</th><th>decoding RMS px</th><th>cloud RMS mm</th><th>p95 mm</th><th>max mm</th>"
            "<th>inside RMS mm</th><th>edge RMS mm</th><th>edge points</th><th>edge share of error&#178;</th>"
            "<th>pose error deg</th><th>pose error mm</th></tr>")
    rows = []
    for v in view_errors:
        c, r, d = v["cloud"], v["registration"], v.get("decoding") or {}
        rows.append("<tr>" + "".join(f"<td>{html.escape(str(x))}</td>" for x in (
            v["view"], _f(d.get("rms_px"), ".3f"), _f(c["rms_mm"], ".4f"), _f(c["p95_mm"], ".4f"),
            _f(c["max_mm"], ".3f"), _f(c["inside"]["rms_mm"], ".4f"), _f(c["edge"]["rms_mm"], ".4f"),
            f"{c['edge']['n']:,}", f"{c['edge_share']:.0%}", _f(r["rotation_deg"], ".4f"),
            _f(r["translation_mm"], ".4f"))) + "</tr>")
    note = ("<p>Each view's cloud against the true surface at its turntable angle; edge points are those seen "
            "within 2 pixels of a silhouette or a depth jump (mixed pixels); decoding compares the decoded "
            "projector column with the true one; the pose error is the registered pose against the true "
            "turntable pose (translation of the object's centre).</p>")
    return ["<h2>Where the error comes from (simulator)</h2>", note, f"<table>{head}{''.join(rows)}</table>"]
