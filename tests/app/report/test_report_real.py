"""The report of a scan without ground truth (a small simulated session with its simulator block removed, as a
hardware session reads): the quality map, coverage map, residual histogram and per-view table are there,
the 3D view turns when dragged in headless Chromium, and the page makes no network request."""

import base64
import json
import re
import shutil

import cv2
import numpy as np
import pytest
import trimesh

from rangekit.app.report.residuals import residual_histogram_svg
from rangekit.app.report.viewer import decimate
from rangekit.app.report.views import saturated_fraction



@pytest.fixture(scope="module")
def report(tmp_path_factory, reference_session):
    from support.sessions import N_VIEWS

    from rangekit.app.process.process import process_session

    out = shutil.copytree(reference_session, tmp_path_factory.mktemp("nogt") / "session")
    data = json.loads((out / "session.json").read_text())
    data.pop("simulator")                      # as a hardware session: nothing to evaluate against
    (out / "session.json").write_text(json.dumps(data, indent=2))
    process_session(out)
    return out / "report.html", N_VIEWS


def _section(page: str, title: str) -> str:
    start = page.index(f"<h2>{title}")
    end = page.find("<h2>", start + 4)
    return page[start:end if end > 0 else None]


def test_report_without_truth_shows_quality_coverage_residuals_and_views(report):
    path, n_views = report
    page = path.read_text()
    assert "hardware" in _section(page, "Summary") and "against the true surface" not in page
    for title in ("3D view", "Views' agreement (no truth needed)", "Coverage (no truth needed)",
                  "Point-to-mesh residuals (no truth needed)", "Per view (no truth needed)"):
        assert f"<h2>{title}</h2>" in page, title
    # Each picture section holds images that decode (2 sides each; the histogram an SVG).
    for title, kind, count in (("Views' agreement", "png", 3), ("Coverage", "png", 2),
                               ("Point-to-mesh residuals", "svg+xml", 1)):
        uris = re.findall(rf'src="data:image/{re.escape(kind)};base64,([^"]+)"', _section(page, title))
        assert len(uris) == count, title
        for u in uris:
            raw = base64.b64decode(u)
            if kind == "png":
                img = cv2.imdecode(np.frombuffer(raw, np.uint8), cv2.IMREAD_COLOR)
                assert img is not None and img.shape[0] > 20 and img.std() > 5, title
            else:
                assert raw.startswith(b"<svg") and raw.endswith(b"</svg>")
    # The coverage legend's shares are of the whole mesh, one per count 0..n.
    shares = [int(s) for s in re.findall(r"\d+: (\d+)%", _section(page, "Coverage"))]
    assert 1 <= len(shares) <= n_views + 1 and abs(sum(shares) - 100) <= len(shares)
    # One row per view with its points and shares; the table does not wrap.
    rows = re.findall(r"<tr[^>]*><td>(view_\d{3})</td><td>([\d,]+)</td><td>([\d.]+)%</td><td>([\d.]+)%</td>"
                      r"<td>([\d.]+)%</td></tr>", _section(page, "Per view"))
    assert [r[0] for r in rows] == [f"view_{k:03d}" for k in range(n_views)]
    for _, pts, decoded, kept, sat in rows:
        assert 0 < float(kept) <= float(decoded) <= 100 and int(pts.replace(",", "")) > 1000 and float(sat) < 1
    assert "td,th{white-space:nowrap}" in page and ".tw{overflow-x:auto" in page
    from rangekit import __version__

    assert f"<th>rangekit</th><td>{__version__}</td>" in page and "<th>command</th>" in page
    assert "colour = view:" in page
    # Self-contained: nothing to fetch, and the policy would block it; a few MB.
    assert "default-src 'none'" in page and not re.search(r"""(src|href)=["']?(https?:|//)""", page)
    assert path.stat().st_size < 8e6


def test_the_3d_view_turns_when_dragged_and_the_page_makes_no_request(report, tmp_path):
    from support.chromium import chromium_paths, open_page

    if chromium_paths() is None:
        pytest.skip("headless browser missing: apt-get install chromium chromium-driver")
    grab = "return document.getElementById('rk-view').toDataURL('image/png');"

    def interact(page):
        canvas = page.element("#rk-view")
        page.execute("arguments[0].scrollIntoView();", canvas)
        before = page.execute(grab)
        page.drag(canvas, 150, 40)
        after = page.execute(grab)
        page.execute("var s = document.getElementById('rk-colour'); s.value = 'views that see it';"
                     "s.dispatchEvent(new Event('change'));")
        recoloured = page.execute(grab)
        requests = page.execute("return performance.getEntriesByType('resource').map(function (e) { return e.name; });")
        return before, after, recoloured, requests

    res = open_page(report[0], interact=interact, timeout_s=60)
    before, after, recoloured, requests = res["interaction"]
    imgs = [cv2.imdecode(np.frombuffer(base64.b64decode(u.split(",", 1)[1]), np.uint8), cv2.IMREAD_COLOR)
            for u in (before, after, recoloured)]
    drawn = np.any(imgs[0] < 250, axis=2)
    assert 0.02 < drawn.mean() < 0.9                          # the mesh is drawn, on white
    changed = np.any(np.abs(imgs[1].astype(int) - imgs[0]) > 30, axis=2).mean()
    assert changed > 0.02, changed                            # dragging turned it
    assert np.any(np.abs(imgs[2].astype(int) - imgs[1]) > 30, axis=2).mean() > 0.01   # the colour scheme applies
    assert requests == []                                     # no resource besides the page itself
    broken = [im for im in res["images"] if not (im["complete"] and im["naturalWidth"] > 0)]
    assert not broken, broken


def test_decimate_keeps_the_surface_within_the_triangle_budget():
    sphere = trimesh.creation.icosphere(subdivisions=5, radius=0.05)     # 20,480 triangles
    V, F = decimate(sphere.vertices, sphere.faces, max_triangles=4000)
    assert 2000 <= len(F) <= 4000 and F.min() == 0 and F.max() == len(V) - 1
    r = np.linalg.norm(V, axis=1)
    assert np.all(np.abs(r - 0.05) < 2e-3)                    # cluster means stay on the surface
    area = trimesh.Trimesh(V, F, process=False).area
    assert abs(area / (4 * np.pi * 0.05 ** 2) - 1) < 0.03     # and cover it
    same_V, same_F = decimate(sphere.vertices, sphere.faces, max_triangles=30_000)   # under budget: unchanged
    assert np.array_equal(same_V[same_F], sphere.vertices[sphere.faces])


def test_saturated_fraction_counts_pixels_at_full_scale_in_any_channel():
    img = np.zeros((10, 20), np.uint16)
    img[:2] = 4095
    assert saturated_fraction(img, 4095.0) == 0.2 and saturated_fraction(img, None) == 0.0
    rgb = np.zeros((10, 10, 3), np.uint8)
    rgb[0, :5, 1] = 255
    assert saturated_fraction(rgb, None) == 0.05


def test_residual_histogram_has_a_bar_per_bin_summing_to_every_point():
    r = np.r_[np.full(300, 1e-5), np.full(100, 3e-5)]
    svg = base64.b64decode(residual_histogram_svg(r, bins=10).split(",", 1)[1]).decode()
    heights = [float(h) for h in re.findall(r'<rect x="[\d.]+" y="[\d.]+" width="[\d.]+" height="([\d.]+)"', svg)]
    assert len(heights) == 10 and max(heights) > 0
    # The tallest bar holds 75% of the points, the 99.5th-percentile bar (clipped into the last) 25%.
    assert np.isclose(sorted(heights)[-2] / max(heights), 1 / 3, atol=1e-3)
