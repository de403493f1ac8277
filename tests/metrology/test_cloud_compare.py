"""rangekit.metrology.cloud_compare against exact answers: a noisy plane's roughness is its noise, a cloud shifted
along the normal is that far from the other, a sphere's curvature adds its known sag, and points where the other
cloud has no neighbours are NaN."""

from __future__ import annotations

import numpy as np

from rangekit.metrology.cloud_compare import distances_to_local_planes, local_planes, roughness


def _plane(n, rng, sigma=0.0, offset=0.0):
    xy = rng.uniform(-0.05, 0.05, (n, 2))
    return np.c_[xy, offset + rng.normal(scale=sigma, size=n) if sigma else np.full(n, offset)]


def test_a_noisy_plane_is_as_rough_as_its_noise():
    rng = np.random.default_rng(0)
    cloud = _plane(200_000, rng, sigma=50e-6)
    at = _plane(500, rng)[:, :2] * 0.8
    r = roughness(cloud, np.c_[at, np.zeros(len(at))], 0.002)
    assert abs(np.median(r) - 50e-6) < 2.5e-6, np.median(r)


def test_a_shifted_cloud_is_its_shift_away():
    rng = np.random.default_rng(1)
    ref = _plane(100_000, rng)
    query = _plane(1000, rng, offset=0.1e-3)[:, :] * [0.8, 0.8, 1]
    d = distances_to_local_planes(query, ref, 0.002)
    np.testing.assert_allclose(d, 0.1e-3, atol=1e-12)


def test_a_sphere_adds_its_sag_and_nothing_else():
    rng = np.random.default_rng(2)
    R, r = 0.05, 0.002
    u = rng.normal(size=(400_000, 3))
    cloud = R * u / np.linalg.norm(u, axis=1, keepdims=True)
    v = rng.normal(size=(300, 3))
    at = R * v / np.linalg.norm(v, axis=1, keepdims=True)
    planes = local_planes(cloud, at, r)
    # The sphere's cap within r of a point, fitted by a plane: its sag rho^2 / (2 R) is uniform over
    # [0, r^2 / (2 R)] on an evenly sampled disc (rho^2 is), so the residual RMS is r^2 / (2 R) / sqrt(12).
    expected = r ** 2 / (2 * R) / np.sqrt(12)
    inside = np.array([np.sum(np.linalg.norm(cloud - a, axis=1) <= r) for a in at[:20]])
    np.testing.assert_array_equal(planes.count[:20], inside)     # every point within r was used, no more
    assert np.all(planes.count >= 6)
    assert 0.9 * expected < np.median(planes.rms) < 1.1 * expected, (np.median(planes.rms), expected)
    # The points themselves lie on the sphere: their distance to the local planes is about the mean sag.
    d = distances_to_local_planes(at, cloud, r)
    assert np.median(d) < r ** 2 / (2 * R)


def test_where_the_other_cloud_is_absent_the_distance_is_nan():
    rng = np.random.default_rng(3)
    ref = _plane(10_000, rng)
    query = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 0.0]])
    d = distances_to_local_planes(query, ref, 0.002)
    assert np.isfinite(d[0]) and np.isnan(d[1])


def test_slstudios_own_cloud_scores_the_roughness_the_issue_states():
    """Issue 35: SLStudio's pointCloud.mat of the skull scores 0.063 mm (plane within 2 mm, median over 4000 of
    its points)."""
    import pytest
    import scipy.io

    from support.shared_data import require_shared

    path = require_shared("slstudio-skull", "skull_gray", "pointCloud.mat")
    xyz = scipy.io.loadmat(path)["xyz"].reshape(-1, 3)          # millimetres
    xyz = xyz[np.isfinite(xyz).all(axis=1)]
    assert len(xyz) == 93_876
    at = xyz[np.random.default_rng(0).choice(len(xyz), 4000, replace=False)]
    assert abs(np.nanmedian(roughness(xyz, at, 2.0)) - 0.063) < 0.001


def test_a_denser_cloud_is_measured_over_the_same_patch():
    """The same curved surface sampled 1x and 16x as densely, without noise: the same roughness at the same
    points (its curvature's sag over the whole 2 mm patch); a cap at the nearest points would give the denser
    cloud a smaller patch and a smaller figure."""
    rng = np.random.default_rng(4)
    R, r = 0.05, 0.002

    def sphere(n):
        u = rng.normal(size=(n, 3))
        return R * u / np.linalg.norm(u, axis=1, keepdims=True)

    at = sphere(200)
    sparse, dense = roughness(sphere(100_000), at, r), roughness(sphere(1_600_000), at, r)
    assert abs(np.median(dense) / np.median(sparse) - 1) < 0.05, (np.median(dense), np.median(sparse))


def test_nearest_planes_give_the_shift_and_its_sign_and_nan_where_uncovered():
    rng = np.random.default_rng(5)
    ref = _plane(50_000, rng, offset=1.0)                      # z = 1 m: the origin (camera) below it
    query = np.r_[_plane(500, rng, offset=1.0003) * [0.8, 0.8, 1], [[2.0, 2.0, 1.0]]]
    from rangekit.metrology.cloud_compare import distances_to_nearest_planes

    d = distances_to_nearest_planes(query, ref, max_radius=0.003, signed=True)
    np.testing.assert_allclose(d[:-1], 0.3e-3, atol=1e-9)     # beyond the surface seen from the origin: +
    assert np.isnan(d[-1])
    np.testing.assert_allclose(distances_to_nearest_planes(query[:-1], ref, max_radius=0.003), 0.3e-3, atol=1e-9)
