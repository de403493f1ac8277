"""The report's interactive 3D view: the observed mesh, decimated, in a small WebGL viewer in the page.

The viewer (``viewer.js``, package data, no library) is inlined in the page with the mesh as base64
float32 vertices (metres, session world) and uint32 triangles, and one uint8 RGB colour per vertex for each
colour scheme (the view whose points lie nearest, the number of views that see it). Nothing is fetched:
the page works offline and under the report's Content-Security-Policy (``default-src 'none'``). Orbit
by dragging with the mouse, zoom with the wheel.
"""

from __future__ import annotations

import base64
import html
import json
from importlib import resources
from typing import Sequence

import numpy as np

from rangekit.surface.topology import unique_rows

__all__ = ["VIEWER_TRIANGLES", "decimate", "viewer_section", "swatch_legend"]

#: The 3D view shows at most this many triangles (the page stays a few MB: 100k triangles are about 2.4 MB).
VIEWER_TRIANGLES = 100_000


def decimate(vertices: np.ndarray, triangles: np.ndarray, max_triangles: int = VIEWER_TRIANGLES
             ) -> tuple[np.ndarray, np.ndarray]:
    """``(V', 3) float64, (T', 3) int64``: the mesh by vertex clustering on a cubic grid, each cell's vertices
    merged at their mean, degenerate and repeated triangles dropped, the cell grown until at most
    ``max_triangles`` remain (the mesh itself, unused vertices dropped, when it has no more)."""
    V = np.asarray(vertices, dtype=np.float64)
    F = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    if len(F) == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), np.int64)
    if len(F) <= max_triangles:
        used, F = np.unique(F, return_inverse=True)
        return V[used], F.reshape(-1, 3)
    lo = V.min(axis=0)
    e = V[F[:, 1]] - V[F[:, 0]]
    cell = float(np.median(np.linalg.norm(e, axis=1))) * np.sqrt(len(F) / max_triangles)
    while True:
        first, group = unique_rows(np.floor((V - lo) / cell).astype(np.int64))
        G = group[F]
        keep = (G[:, 0] != G[:, 1]) & (G[:, 1] != G[:, 2]) & (G[:, 0] != G[:, 2])
        G = G[keep]
        G = G[unique_rows(np.sort(G, axis=1))[0]]
        if len(G) <= max_triangles:
            break
        cell *= 1.1
    counts = np.bincount(group, minlength=len(first)).astype(np.float64)
    W = np.column_stack([np.bincount(group, weights=V[:, j], minlength=len(first)) for j in range(3)]) / counts[:, None]
    used, G = np.unique(G, return_inverse=True)
    return W[used], G.reshape(-1, 3)


def swatch_legend(colours: np.ndarray, labels: Sequence[str], *, title: str, name: str | None = None) -> str:
    """HTML legend: a coloured square per entry (``colours`` (K, 3) uint8 RGB) with its label; ``name`` makes
    it a 3D-view legend shown only while that colour scheme is selected."""
    items = "".join(f"<span class='sw'><i style='background:rgb({c[0]},{c[1]},{c[2]})'></i>{html.escape(t)}</span>"
                    for c, t in zip(np.asarray(colours, dtype=np.uint8), labels))
    attr = "" if name is None else f" class='rk-legend' data-colour='{html.escape(name)}'"
    return f"<div{attr}><b>{html.escape(title)}</b> {items}</div>"


def _b64(a: np.ndarray) -> str:
    return base64.b64encode(np.ascontiguousarray(a).tobytes()).decode("ascii")


def viewer_section(vertices: np.ndarray, triangles: np.ndarray, schemes: dict, *, up: np.ndarray,
                   legends: Sequence[str], of: int | None = None, size: tuple[int, int] = (720, 540)) -> list[str]:
    """HTML of the 3D view of a mesh already decimated (``vertices`` (V, 3) metres, ``triangles`` (T, 3), ``of``
    the triangles of the mesh it was decimated from);
    ``schemes`` maps a colour scheme's label to its (V, 3) uint8 RGB vertex colours (the first is shown
    first), ``legends`` the HTML of each scheme's legend (:func:`swatch_legend` with ``name`` = its label),
    ``up`` the direction the orbit turns about."""
    V = np.asarray(vertices, dtype=np.float64)
    centre = 0.5 * (V.min(axis=0) + V.max(axis=0))
    radius = float(np.linalg.norm(V - centre, axis=1).max()) or 1.0
    spec = {"pos": _b64((V - centre).astype("<f4")), "idx": _b64(np.asarray(triangles).astype("<u4")),
            "colours": {k: _b64(np.asarray(c, dtype=np.uint8)) for k, c in schemes.items()},
            "centre": [0.0, 0.0, 0.0], "radius": radius, "up": [float(u) for u in up]}
    js = resources.files("rangekit.app.report").joinpath("viewer.js").read_text(encoding="utf-8")
    options = "".join(f"<option>{html.escape(k)}</option>" for k in schemes)
    data = json.dumps(spec).replace("</", "<\\/")
    return ["<h2>3D view</h2>",
            f"<p>The observed mesh ({len(triangles):,} triangles"
            + (f", decimated from {of:,}" if of is not None and of > len(triangles) else "")
            + "): drag to turn it, scroll to zoom. Colour: <select id='rk-colour'>" + options + "</select></p>",
            f"<canvas id='rk-view' width='{size[0]}' height='{size[1]}' style='border:1px solid #ddd;cursor:grab;"
            "touch-action:none'></canvas>", "".join(legends),
            f"<script type='application/json' id='rk-mesh'>{data}</script>", f"<script>{js}</script>"]
