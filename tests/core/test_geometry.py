"""Transforms, rotations and Procrustes against exact answers."""

import numpy as np
import pytest
from scipy.optimize import minimize

from rangekit.errors import InputError
from rangekit.geometry import (R_to_quat, R_to_rotvec, apply_T, axis_angle_to_R, compose, invert_T, look_at,
                               make_T, nearest_rotation, procrustes, quat_to_R, rotation_angle, rotvec_to_R,
                               transform_vectors)


def random_similarity(rng, scale=True):
    R = rotvec_to_R(rng.normal(size=3))
    s = rng.uniform(0.5, 2.0) if scale else 1.0
    return make_T(R, rng.normal(size=3), scale=s), R, s


def test_invert_and_compose_similarity_exactly():
    rng = np.random.default_rng(1)
    T, _, _ = random_similarity(rng)
    assert np.abs(invert_T(T) @ T - np.eye(4)).max() < 1e-12
    A, _, _ = random_similarity(rng)
    P = rng.normal(size=(50, 3))
    assert np.abs(apply_T(compose(A, T), P) - apply_T(A, apply_T(T, P))).max() < 1e-12
    homog = (compose(A, T) @ np.c_[P, np.ones(50)].T).T[:, :3]
    assert np.abs(apply_T(compose(A, T), P) - homog).max() < 1e-12


def test_rotation_conversions_round_trip():
    rng = np.random.default_rng(2)
    for _ in range(20):
        rv = rng.normal(size=3)
        rv *= rng.uniform(0, np.pi - 1e-3) / np.linalg.norm(rv)
        R = rotvec_to_R(rv)
        assert np.abs(R_to_rotvec(R) - rv).max() < 1e-10
        assert np.abs(quat_to_R(R_to_quat(R)) - R).max() < 1e-12
        assert abs(rotation_angle(R) - np.linalg.norm(rv)) < 1e-10
    R = axis_angle_to_R([0, 0, 2.0], np.pi / 2)
    assert np.abs(R @ [1, 0, 0] - [0, 1, 0]).max() < 1e-15
    assert abs(rotation_angle(rotvec_to_R([1e-9, 0, 0])) - 1e-9) < 1e-20


def test_nearest_rotation_has_det_plus_one_and_is_closest():
    rng = np.random.default_rng(3)
    R = rotvec_to_R(rng.normal(size=3))
    assert np.abs(nearest_rotation(R) - R).max() < 1e-14
    reflection = R @ np.diag([1, 1, -1])
    Q = nearest_rotation(reflection)
    assert np.isclose(np.linalg.det(Q), 1.0)
    M = R + 0.05 * rng.normal(size=(3, 3))
    Q = nearest_rotation(M)
    assert np.abs(Q @ Q.T - np.eye(3)).max() < 1e-14
    # No other rotation nearby is closer to M.
    for _ in range(200):
        other = rotvec_to_R(R_to_rotvec(Q) + 0.01 * rng.normal(size=3))
        assert np.linalg.norm(M - Q) <= np.linalg.norm(M - other) + 1e-15


def test_look_at_is_an_opencv_camera():
    T = look_at([0.3, -0.4, 0.2], [0, 0, 0.05], up=[0, 0, 1])
    R = T[:3, :3]
    assert np.isclose(np.linalg.det(R), 1.0)
    fwd = np.array([0, 0, 0.05]) - [0.3, -0.4, 0.2]
    assert np.abs(R[:, 2] - fwd / np.linalg.norm(fwd)).max() < 1e-15
    assert R[:, 1] @ [0, 0, 1] < 0  # image y (down) points away from world up
    assert abs(R[:, 0] @ [0, 0, 1]) < 1e-15  # no roll: image x is horizontal


def test_procrustes_recovers_similarity_exactly():
    rng = np.random.default_rng(4)
    for scale in (True, False):
        T, R, s = random_similarity(rng, scale)
        src = rng.normal(size=(30, 3))
        res = procrustes(src, apply_T(T, src), scale=scale)
        assert np.abs(res.T_dst_src - T).max() < 1e-10
        assert abs(res.scale - s) < 1e-10 and res.rmse < 1e-10
        assert np.abs(res.R - R).max() < 1e-10


def test_procrustes_weights_ignore_outliers_and_match_weighted_optimum():
    rng = np.random.default_rng(5)
    T, _, _ = random_similarity(rng)
    src = rng.normal(size=(40, 3))
    dst = apply_T(T, src)
    dst[:8] += rng.normal(scale=5.0, size=(8, 3))  # gross outliers
    w = np.ones(40)
    w[:8] = 0
    res = procrustes(src, dst, weights=w, scale=True)
    assert np.abs(res.T_dst_src - T).max() < 1e-10
    # A NaN row with weight 0 is ignored by the fit and reported as a NaN residual.
    with_nan = procrustes(np.r_[src, [[np.nan] * 3]], np.r_[dst, [[0, 0, 0]]], weights=np.r_[w, 0], scale=True)
    assert np.isnan(with_nan.residuals[-1]) and np.abs(with_nan.T_dst_src - T).max() < 1e-10
    # Noisy data, random weights: the closed form equals a numerical minimiser of the weighted cost.
    dst = apply_T(T, src) + rng.normal(scale=0.01, size=src.shape)
    w = rng.uniform(0.1, 3.0, size=40)
    res = procrustes(src, dst, weights=w, scale=True)

    def cost(x):
        Tx = make_T(rotvec_to_R(x[:3]), x[3:6], scale=np.exp(x[6]))
        return np.sum(w * np.sum((dst - apply_T(Tx, src)) ** 2, axis=1))

    x0 = np.r_[R_to_rotvec(res.R), res.t, np.log(res.scale)]
    num = minimize(cost, x0 + 0.01, method="BFGS", options={"gtol": 1e-12})
    assert cost(x0) <= num.fun + 1e-12
    unweighted = procrustes(src, dst, scale=True)
    assert cost(x0) < cost(np.r_[R_to_rotvec(unweighted.R), unweighted.t, np.log(unweighted.scale)])


def test_procrustes_with_noise_matches_noise_level():
    rng = np.random.default_rng(6)
    T, R, _ = random_similarity(rng, scale=False)
    sigma = 1e-3
    src = rng.uniform(-0.1, 0.1, size=(2000, 3))
    dst = apply_T(T, src) + rng.normal(scale=sigma, size=src.shape)
    res = procrustes(src, dst)
    expected = sigma * np.sqrt(3 * (len(src) - 2) / len(src))  # 6 dof removed from 3N residuals
    assert abs(res.rmse / expected - 1) < 0.05
    assert np.degrees(rotation_angle(res.R.T @ R)) < 0.05


def test_procrustes_bad_input_is_clear():
    with pytest.raises(InputError, match="collinear"):
        line = np.outer(np.arange(5.0), [1, 2, 3])
        procrustes(line, line + 1)
    with pytest.raises(InputError, match="shape"):
        procrustes(np.zeros((4, 3)), np.zeros((5, 3)))
    with pytest.raises(InputError, match="at least 3"):
        procrustes(np.eye(3), np.eye(3), weights=[1, 1, 0])
    with pytest.raises(InputError, match=r"\(N, 3\)"):
        procrustes(np.zeros((4, 2)), np.zeros((4, 2)))


def test_transform_vectors_ignores_translation_and_scale():
    T = make_T(axis_angle_to_R([0, 0, 1], np.pi / 2), [5, 5, 5], scale=3.0)
    assert np.abs(transform_vectors(T, np.array([[1.0, 0, 0]])) - [0, 1, 0]).max() < 1e-15


def test_rigid_problem_names_what_is_wrong():
    from rangekit.geometry import axis_angle_to_R, make_T, rigid_problem

    T = make_T(axis_angle_to_R([1.0, 2.0, 3.0], 0.7), [0.1, -0.2, 0.3])
    assert rigid_problem(T) is None
    assert "reflection" in rigid_problem(T @ np.diag([1.0, 1.0, -1.0, 1.0]))
    assert "non-finite" in rigid_problem(np.where(np.eye(4) > 0, np.nan, T))
    scaled = T.copy()
    scaled[:3, :3] *= 1.001
    assert "R R^T - I" in rigid_problem(scaled) and rigid_problem(scaled, tol=0.01) is None
    bottom = T.copy()
    bottom[3, 2] = 1.0
    assert "last row" in rigid_problem(bottom)
    assert "shape (3, 4)" in rigid_problem(T[:3])


def test_cross_rows_is_np_cross_bit_for_bit():
    """cross_rows (the truth evaluation's ray hits and normals) gives np.cross's very bits: rows, one vector
    against rows, float32 rows against float64 rows."""
    from rangekit.geometry import cross_rows

    rng = np.random.default_rng(5)
    a, b = rng.standard_normal((1000, 3)) * 1e-3, rng.standard_normal((1000, 3)) + 0.05
    assert np.array_equal(cross_rows(a, b), np.cross(a, b))
    assert np.array_equal(cross_rows(a, b[0]), np.cross(a, b[0]))
    assert np.array_equal(cross_rows(b[0], a), np.cross(b[0], a))
    f = a.astype(np.float32)
    assert np.array_equal(cross_rows(f, b), np.cross(f, b))
    assert cross_rows(a, b).dtype == np.float64
