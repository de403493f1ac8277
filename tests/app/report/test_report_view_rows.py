"""The report's per-view part made ahead of the mesh (rangekit.app.report.view_rows): each view's maps read
once, in order, and not kept; the sigma pictures on one scale over all views, as from maps held in memory."""

import re

import numpy as np

from rangekit.app.report.view_rows import _compact, _expand, view_rows
from rangekit.formats.sessions.view_maps import ViewMaps
from rangekit.sim.devices.sim_rig import default_rig
from rangekit.surface.cloud import PointCloud


def views(n=3, shape=(60, 80), seed=0):
    rng = np.random.default_rng(seed)
    maps, clouds = [], []
    for k in range(n):
        col = rng.uniform(0, 1000, shape).astype(np.float32)
        col[:10] = np.nan
        depth = np.where(np.isfinite(col), 0.3 + 0.01 * k, np.nan).astype(np.float32)
        sigma = np.where(np.isfinite(depth), rng.uniform(1e-5, (k + 1) * 1e-4, shape), np.nan).astype(np.float32)
        capture = rng.integers(0, 256, shape, dtype=np.uint8)
        maps.append(ViewMaps(col, rng.uniform(0, 1, shape).astype(np.float32), depth, capture, sigma))
        clouds.append(PointCloud(rng.normal(size=(500, 3)) * 0.01 + [0, 0, 0.3]))
    return maps, clouds


def test_compact_sigma_comes_back_with_its_nans():
    sigma = np.array([[np.nan, 1.0], [2.0, np.nan]], dtype=np.float32)
    back = _expand(_compact(sigma))
    assert back.dtype == np.float32 and np.array_equal(np.isnan(back), np.isnan(sigma))
    assert np.array_equal(back[np.isfinite(back)], [1.0, 2.0])
    assert _compact(None) is None and _compact(np.full((2, 2), np.nan)) is None


def test_each_views_maps_are_read_once_in_order_and_the_sigma_scale_spans_all_views():
    maps, clouds = views()
    asked = []

    def load(k):
        asked.append(k)
        return maps[k]

    rig, up = default_rig(), np.array([0.0, 0.0, 1.0])
    rows = view_rows(["a", "b", "c"], clouds, load, rig=rig, full_scale=255, up=up)
    assert asked == [0, 1, 2]
    html = "".join(rows.views)
    assert html.count("<div class='row'>") == 3 and html.count("<figure>") == 3 * 6
    top = np.percentile(np.concatenate([m.sigma[np.isfinite(m.sigma)] for m in maps]), 99)
    assert re.findall(r"<figcaption>predicted sigma 0-([0-9.]+) mm", html) == [f"{top * 1e3:.3f}"] * 3
    table = "".join(rows.table)
    assert table.count("<tr>") == 1 + 3 and "83.3%" in table    # 50 of 60 rows decoded
