"""The report's quality map on a mesh whose views disagree by a known height."""

import numpy as np

from rangekit.app.report.quality import QUALITY_VERTICES, mesh_quality, sigma_scale


def _grid(n: int, step: float, z: float) -> np.ndarray:
    u, v = np.meshgrid(np.arange(n) * step, np.arange(n) * step)
    return np.column_stack([u.ravel(), v.ravel(), np.full(u.size, z)])


def test_two_views_a_known_height_apart_disagree_by_that_height_over_root_two():
    # Mesh: a 100 x 100 grid of 1 mm cells at z = 0; view A's points at z = 0, view B's 0.05 mm above,
    # both sampled every 0.5 mm and offset half a step from the vertices.
    n = 100
    V = _grid(n, 1e-3, 0.0)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    F = np.concatenate([np.column_stack([a, b, d]), np.column_stack([a, d, c])])
    A = _grid(2 * n, 0.5e-3, 0.0) + [0.25e-3, 0.25e-3, 0]
    B = _grid(2 * n, 0.5e-3, 0.05e-3) + [0.25e-3, 0.25e-3, 0]
    used, q = mesh_quality(V, F, [A, B])
    assert len(used) == len(V) <= QUALITY_VERTICES
    interior = np.all((used[:, :2] > 3e-3) & (used[:, :2] < (n - 4) * 1e-3), axis=1)
    assert np.allclose(q.disagreement[interior], 0.05e-3 / np.sqrt(2), rtol=1e-6)
    assert np.all(q.n_views[interior] == 2)
    # Only view A sees a vertex: NaN, nothing to compare.
    used, q = mesh_quality(V, F, [A, B[B[:, 0] > 50e-3]])
    left = used[:, 0] < 45e-3
    assert np.all(np.isnan(q.disagreement[left])) and np.all(q.n_views[left] == 1)


def test_sigma_scale_is_the_99th_percentile_over_all_views_ignoring_nan():
    maps = [np.full((10, 10), np.nan), np.linspace(0, 1e-3, 100).reshape(10, 10)]
    assert np.isclose(sigma_scale(maps), np.percentile(np.linspace(0, 1e-3, 100), 99))
    assert sigma_scale([np.full((2, 2), np.nan)]) == 1e-3
