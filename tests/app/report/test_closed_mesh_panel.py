"""The report's closed-mesh panel shows which parts of mesh_watertight.ply are observed, carved or guessed."""

from __future__ import annotations

import base64
import re

import numpy as np

from rangekit.app.report.context import CARVED_COLOUR, INVENTED_COLOUR, OBSERVED_COLOUR, ReportContext
from rangekit.app.report.panels import closed_mesh_panel
from rangekit.formats.sessions.session import Session
from rangekit.io import read_png
from rangekit.surface.mesh import TriangleMesh


def _sphere(n: int = 40) -> TriangleMesh:
    import open3d as o3d

    m = o3d.geometry.TriangleMesh.create_sphere(radius=0.05, resolution=n)
    return TriangleMesh(np.asarray(m.vertices), np.asarray(m.triangles))


def _colours_seen(html: str, folder) -> set:
    """Which of the three flag colours the panel's pictures show (hue, on lit pixels)."""
    seen = set()
    for data in re.findall(r"data:image/png;base64,([A-Za-z0-9+/=]+)", html):
        (folder / "picture.png").write_bytes(base64.b64decode(data))
        rgb = read_png(folder / "picture.png")[..., :3].astype(float).reshape(-1, 3)
        lit = rgb[rgb.max(axis=1) > 40]
        for name, c in (("observed", OBSERVED_COLOUR), ("carved", CARVED_COLOUR), ("guessed", INVENTED_COLOUR)):
            c = np.array(c)
            # the same chromaticity as the flag's colour, whatever the shading's brightness
            chroma = lit / lit.sum(axis=1, keepdims=True)
            if np.any(np.linalg.norm(chroma - c / c.sum(), axis=1) < 0.01):
                seen.add(name)
    return seen


def test_the_panel_colours_each_flag(reference_session, tmp_path):
    mesh = _sphere()
    z = mesh.vertices[:, 2]
    observed, carved = z > -0.01, z < -0.03          # a band of guessed vertices between them
    closed = TriangleMesh(mesh.vertices, mesh.triangles, None, observed, carved)
    ctx = ReportContext(tmp_path, None, Session.load(reference_session), mesh, watertight=closed, size=(120, 120))
    html = closed_mesh_panel(ctx)
    shares = [float(s) for s in re.findall(r"\(([\d.]+)% of its vertices", html) + re.findall(r"\(([\d.]+)%, ", html)]
    assert shares == [round(100 * (carved & ~observed).mean(), 1), round(100 * (~observed & ~carved).mean(), 1)]
    assert "carved = 1" in html
    assert _colours_seen(html, tmp_path) == {"observed", "carved", "guessed"}
    only_observed = TriangleMesh(mesh.vertices, mesh.triangles, None, np.ones(len(z), bool))   # no carved flag: none orange
    assert _colours_seen(closed_mesh_panel(ReportContext(tmp_path, None, Session.load(reference_session), mesh,
                                                         watertight=only_observed, size=(120, 120))), tmp_path) \
        <= {"observed", "guessed"}     # (grey has no hue: the page's own greys match it)
