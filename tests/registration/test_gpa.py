"""Generalised Procrustes Analysis against exact ground truth, with missing landmarks."""

import numpy as np
import pytest

from rangekit.errors import InputError
from rangekit.geometry import apply_T, invert_T, make_T, rotation_angle, rotvec_to_R
from rangekit.registration.gpa import gpa


def make_sets(rng, m=10, N=100, missing=0.3, sigma=0.0, scale=False):
    """m views of one shape (0.2 m across); set i = inv(T_world_i) @ shape (+ noise), NaN where missing.

    Returns the sets, the true T_world_set expressed in set 0's frame, the shape in that frame and the
    presence mask.
    """
    shape = rng.uniform(-0.1, 0.1, size=(N, 3))
    T_true = [make_T(rotvec_to_R(rng.normal(size=3)), rng.normal(scale=0.3, size=3),
                     scale=rng.uniform(0.5, 2.0) if scale else 1.0) for _ in range(m)]
    present = rng.random((m, N)) >= missing
    sets = []
    for i in range(m):
        B = apply_T(invert_T(T_true[i]), shape) + rng.normal(scale=sigma, size=(N, 3))
        B[~present[i]] = np.nan
        sets.append(B)
    T0_inv = invert_T(T_true[0])
    truth = np.stack([T0_inv @ T for T in T_true])
    return sets, truth, apply_T(T0_inv, shape), present


def test_rigid_noise_free_missing_data_recovers_ground_truth():
    rng = np.random.default_rng(0)
    sets, truth, shape0, present = make_sets(rng)
    assert 0.25 < 1 - present.mean() < 0.35
    res = gpa(sets)
    assert res.converged, res.reason
    assert np.array_equal(res.T_world_set[0], np.eye(4))
    assert np.abs(res.T_world_set - truth).max() < 1e-8
    seen = present.any(axis=0)
    assert np.abs(res.centroid[seen] - shape0[seen]).max() < 1e-8
    assert res.rmse < 1e-10
    assert res.residuals.shape == (10, 100)
    assert np.array_equal(np.isnan(res.residuals), ~present)


def test_chain_of_partial_overlaps():
    """Set i sees landmarks [10 i, 10 i + 25): each overlaps only its neighbours (tests the greedy start)."""
    rng = np.random.default_rng(1)
    sets, truth, shape0, _ = make_sets(rng, m=8, N=95, missing=0.0)
    for i, B in enumerate(sets):
        keep = np.zeros(95, dtype=bool)
        keep[10 * i:10 * i + 25] = True
        B[~keep] = np.nan
    res = gpa(sets)
    assert res.converged
    assert np.abs(res.T_world_set - truth).max() < 1e-8
    assert np.abs(res.centroid - shape0).max() < 1e-8


def test_rigid_noise_rmse_matches_sigma():
    rng = np.random.default_rng(2)
    sigma = 2e-4
    sets, truth, _, present = make_sets(rng, sigma=sigma)
    res = gpa(sets)
    assert res.converged, res.reason
    m = len(sets)
    n_obs = present.sum()
    # Degrees of freedom of the residual: 3 per observation, minus 3 per consensus landmark, minus 6
    # per set beyond the gauge (set 0).
    dof = 3 * n_obs - 3 * present.any(axis=0).sum() - 6 * (m - 1)
    expected = sigma * np.sqrt(dof / n_obs)
    assert abs(res.rmse / expected - 1) < 0.15, (res.rmse, expected)
    for T, Tt in zip(res.T_world_set, truth):
        assert np.degrees(rotation_angle(T[:3, :3].T @ Tt[:3, :3])) < 0.1  # ~ sigma / (size * sqrt(N))
        assert np.linalg.norm(T[:3, 3] - Tt[:3, 3]) < 10 * sigma


def test_similarity_recovers_scales_noise_free():
    rng = np.random.default_rng(3)
    sets, truth, shape0, present = make_sets(rng, scale=True)
    res = gpa(sets, scale=True)
    assert res.converged, res.reason
    true_scales = np.cbrt(np.linalg.det(truth[:, :3, :3]))
    assert np.abs(res.scales - true_scales).max() < 1e-8
    assert np.abs(res.T_world_set - truth).max() < 1e-8
    seen = present.any(axis=0)
    assert np.abs(res.centroid[seen] - shape0[seen]).max() < 1e-8


def test_similarity_with_noise_does_not_shrink():
    rng = np.random.default_rng(4)
    sets, truth, shape0, _ = make_sets(rng, scale=True, sigma=1e-4)
    res = gpa(sets, scale=True)
    assert res.converged, res.reason
    true_scales = np.cbrt(np.linalg.det(truth[:, :3, :3]))
    assert np.abs(res.scales / true_scales - 1).max() < 5e-3
    size = np.sqrt(np.nanmean(np.sum((res.centroid - np.nanmean(res.centroid, 0)) ** 2, 1)))
    size_true = np.sqrt(np.mean(np.sum((shape0 - shape0.mean(0)) ** 2, 1)))
    assert abs(size / size_true - 1) < 5e-3


def test_rigid_gpa_of_scaled_sets_keeps_unit_scale():
    rng = np.random.default_rng(5)
    sets, _, _, _ = make_sets(rng, m=4, scale=True)
    res = gpa(sets)
    assert np.allclose(res.scales, 1.0, atol=1e-12)
    assert res.rmse > 1e-3  # the shapes differ in size, so a rigid fit cannot be exact


def test_landmark_seen_by_no_set_and_zero_weights():
    rng = np.random.default_rng(6)
    sets, truth, _, _ = make_sets(rng, m=5, N=40, missing=0.0)
    for i, B in enumerate(sets):
        B[7] = np.nan                      # landmark 7: seen by nobody
        B[10 + i] = np.nan                 # one more missing per set
    sets[3][20, 0] += 0.05                 # a wrong landmark, switched off by its weight
    weights = np.ones((5, 40))
    weights[3, 20] = 0.0
    res = gpa(sets, weights=weights)
    assert np.all(np.isnan(res.centroid[7])) and np.all(np.isnan(res.residuals[:, 7]))
    assert np.abs(res.T_world_set - truth).max() < 1e-8
    assert abs(res.residuals[3, 20] - 0.05) < 1e-8  # reported, but it did not pull the fit
    # Without the zero weight the wrong landmark spoils the fit.
    assert np.abs(gpa(sets).T_world_set - truth).max() > 1e-4


def test_input_errors_name_the_set():
    rng = np.random.default_rng(7)
    sets, _, _, _ = make_sets(rng, m=4, N=30, missing=0.0)
    with pytest.raises(InputError, match="at least 2"):
        gpa(sets[:1])
    with pytest.raises(InputError, match="set 2 has 29"):
        gpa([sets[0], sets[1], sets[2][:29], sets[3]])
    bad = [B.copy() for B in sets]
    bad[1][2:] = np.nan
    with pytest.raises(InputError, match="set 1 has 2 present landmarks"):
        gpa(bad)
    bad = [B.copy() for B in sets]
    bad[2][5, 1] = np.nan
    with pytest.raises(InputError, match="set 2 has rows with some but not all"):
        gpa(bad)
    with pytest.raises(InputError, match=r"set 0 must be an \(N, 3\)"):
        gpa([sets[0][:, :2], sets[1]])
    with pytest.raises(InputError, match="weights must have shape"):
        gpa(sets, weights=np.ones(3))
    # Sets 2 and 3 see landmarks 15..29 only, sets 0 and 1 see 0..14: two groups, no common landmark.
    split = [B.copy() for B in sets]
    for i in (0, 1):
        split[i][15:] = np.nan
    for i in (2, 3):
        split[i][:15] = np.nan
    with pytest.raises(InputError, match=r"sets \[.*\] share fewer than 3 landmarks"):
        gpa(split)
    # Collinear landmarks.
    line = np.outer(np.linspace(0, 1, 30), [1.0, 2.0, 3.0])
    with pytest.raises(InputError, match="set 1 cannot be aligned"):
        gpa([sets[0], line])
