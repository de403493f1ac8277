"""Rotation and translation synchronisation against ground truth, with and without wrong edges."""

import numpy as np
import pytest

from rangekit.errors import InputError, RegistrationError
from rangekit.geometry import apply_T, axis_angle_to_R, invert_T, make_T, rotation_angle, rotvec_to_R
from rangekit.registration.view_graph import EdgesDisagree
from rangekit.registration.sync import synchronise, synchronise_rotations, synchronise_translations

SCENE = 1.0  # metres: the ring's diameter


def turntable(rng, n=12, radius=0.5):
    """True T_world_view of n views around a ring (wobbling a little), expressed in view 0's frame."""
    Ts = []
    for k in range(n):
        a = 2 * np.pi * k / n
        R = axis_angle_to_R([0, 0, 1], a) @ rotvec_to_R(rng.normal(scale=0.05, size=3))
        Ts.append(make_T(R, [radius * np.cos(a), radius * np.sin(a), rng.normal(scale=0.02)]))
    T0_inv = invert_T(Ts[0])
    return np.stack([T0_inv @ T for T in Ts])


def ring_pairs(n=12, hops=(1, 2, 3)):
    return [(k, (k + d) % n) for k in range(n) for d in hops]


def random_poses(rng, n):
    Ts = [make_T(rotvec_to_R(rng.normal(size=3)), rng.uniform(-0.5, 0.5, size=3)) for _ in range(n)]
    T0_inv = invert_T(Ts[0])
    return np.stack([T0_inv @ T for T in Ts])


def random_pairs(rng, n, p=0.35):
    """A connected random graph: a random spanning tree plus each other pair with probability p."""
    order = rng.permutation(n)
    pairs = {tuple(sorted((int(order[k]), int(order[rng.integers(k)])))) for k in range(1, n)}
    for i in range(n):
        for j in range(i + 1, n):
            if rng.random() < p:
                pairs.add((i, j))
    return sorted(pairs)


def measure(T, pairs, rng, rot_noise=0.0, t_noise=0.0, n_bad=0, bad_rotation=True):
    """Edges (i, j, T_i_j) with noise (rot_noise: total angle scale in radians); n_bad wrong ones."""
    bad = rng.choice(len(pairs), n_bad, replace=False)
    edges = []
    for e, (i, j) in enumerate(pairs):
        T_ij = invert_T(T[i]) @ T[j]
        R = T_ij[:3, :3] @ rotvec_to_R(rng.normal(scale=rot_noise / np.sqrt(3), size=3))
        t = T_ij[:3, 3] + rng.normal(scale=t_noise, size=3)
        if e in bad:
            if bad_rotation:
                axis = rng.normal(size=3)
                R = R @ rotvec_to_R(axis / np.linalg.norm(axis) * np.radians(rng.uniform(30, 180)))
            t = t + rng.normal(scale=0.3, size=3)
        edges.append((i, j, make_T(R, t)))
    is_bad = np.zeros(len(pairs), dtype=bool)
    is_bad[bad] = True
    return edges, is_bad


def pose_errors(T_est, T_true):
    """Mean rotation error (degrees) and mean position error (metres) over the views."""
    rot = [np.degrees(rotation_angle(a[:3, :3].T @ b[:3, :3])) for a, b in zip(T_est, T_true)]
    return float(np.mean(rot)), float(np.mean(np.linalg.norm(T_est[:, :3, 3] - T_true[:, :3, 3], axis=1)))


def test_convention_T_i_j_maps_view_j_into_view_i():
    """Three views, checked by mapping points: p_i = T_i_j @ p_j and p_world = T_world_view @ p_view."""
    rng = np.random.default_rng(0)
    T = random_poses(rng, 3)
    P_world = rng.normal(size=(20, 3))
    P = [apply_T(invert_T(Ti), P_world) for Ti in T]  # each view's own coordinates
    T_01 = invert_T(T[0]) @ T[1]
    assert np.abs(apply_T(T_01, P[1]) - P[0]).max() < 1e-12
    edges = [(0, 1, T_01), (2, 1, invert_T(T[2]) @ T[1]), (0, 2, invert_T(T[0]) @ T[2])]
    res = synchronise(3, edges)
    for k in range(3):
        assert np.abs(apply_T(res.T_world_view[k], P[k]) - P_world).max() < 1e-9


@pytest.mark.parametrize("robust", [True, False])
def test_noise_free_exact_recovery(robust):
    rng = np.random.default_rng(1)
    T = turntable(rng)
    edges, _ = measure(T, ring_pairs(), rng)
    res = synchronise(12, edges, robust=robust)
    assert np.array_equal(res.T_world_view[0], np.eye(4))
    assert np.abs(res.T_world_view - T).max() < 1e-9
    assert res.edge_rotation_error.max() < 1e-9 and res.edge_translation_error.max() < 1e-9
    assert res.inlier.all()
    # The same through the two public steps, with a random graph and edges in either direction.
    T = random_poses(rng, 15)
    pairs = [(j, i) if rng.random() < 0.5 else (i, j) for i, j in random_pairs(rng, 15)]
    edges, _ = measure(T, pairs, rng)
    R_world, rot_err, inl = synchronise_rotations(15, edges, robust=robust)
    assert np.abs(R_world - T[:, :3, :3]).max() < 1e-9 and rot_err.max() < 1e-9 and inl.all()
    t_world, t_err, inl = synchronise_translations(15, edges, R_world, robust=robust)
    assert np.abs(t_world - T[:, :3, 3]).max() < 1e-9 and t_err.max() < 1e-9 and inl.all()


def test_dict_edges_and_weights():
    rng = np.random.default_rng(2)
    T = turntable(rng, n=8)
    edges, is_bad = measure(T, ring_pairs(8), rng, n_bad=2)
    as_dict = {(i, j): T_ij for i, j, T_ij in edges}
    res = synchronise(8, as_dict, robust=False, weights=(~is_bad).astype(float))  # weight 0 drops an edge
    assert np.abs(res.T_world_view - T).max() < 1e-9
    assert np.all(res.edge_rotation_error[is_bad] > np.radians(20))


def test_noisy_recovery_at_noise_level():
    rng = np.random.default_rng(3)
    T = turntable(rng)
    rot_noise, t_noise = np.radians(0.05), 1e-4
    edges, _ = measure(T, ring_pairs(), rng, rot_noise=rot_noise, t_noise=t_noise)
    res = synchronise(12, edges)
    plain = synchronise(12, edges, robust=False)
    assert res.inlier.all()  # no good edge rejected
    rot, pos = pose_errors(res.T_world_view, T)
    assert rot < np.degrees(rot_noise)            # averaging over the graph beats a single edge
    assert pos < 0.5 * np.degrees(rot_noise) * np.pi / 180 * SCENE + 3 * t_noise
    assert np.abs(res.T_world_view - plain.T_world_view).max() < 1e-12
    assert np.median(res.edge_rotation_error) < 2 * rot_noise
    assert "robust" in res.method and "spectral" in plain.method


@pytest.mark.parametrize("seed", [0, 1, 2, 3, 4])
def test_outliers_robust_vs_plain(seed):
    """12 views, 36 edges, 15 % of them wrong (30-180 deg off, translations 0.3 m off)."""
    rng = np.random.default_rng(100 + seed)
    T = turntable(rng)
    pairs = ring_pairs()
    edges, is_bad = measure(T, pairs, rng, rot_noise=np.radians(0.002), t_noise=1e-5,
                            n_bad=round(0.15 * len(pairs)))
    assert len(pairs) == 36 and is_bad.sum() == 5
    res = synchronise(12, edges)
    rot, pos = pose_errors(res.T_world_view, T)
    assert rot < 0.005, rot
    assert pos < 1e-4 * SCENE, pos
    assert np.array_equal(res.inlier, ~is_bad)
    assert np.all(res.edge_rotation_error[is_bad] > np.radians(20))
    plain = synchronise(12, edges, robust=False)
    rot_p, pos_p = pose_errors(plain.T_world_view, T)
    assert rot_p > 1.0 and pos_p > 1e-2 * SCENE, (rot_p, pos_p)  # visibly corrupted
    assert plain.inlier.all()


def test_translation_outliers_on_random_graph():
    """Exact rotations, 10 % of the translations wrong: robust least squares ignores them."""
    rng = np.random.default_rng(5)
    n = 20
    T = random_poses(rng, n)
    pairs = random_pairs(rng, n, p=0.4)
    edges, is_bad = measure(T, pairs, rng, t_noise=1e-6, n_bad=round(0.1 * len(pairs)), bad_rotation=False)
    t_world, err, inlier = synchronise_translations(n, edges, T[:, :3, :3])
    assert np.abs(t_world - T[:, :3, 3]).max() < 1e-5
    assert np.array_equal(inlier, ~is_bad)
    assert np.all(err[is_bad] > 0.05)
    t_plain, _, _ = synchronise_translations(n, edges, T[:, :3, :3], robust=False)
    assert np.abs(t_plain - T[:, :3, 3]).max() > 1e-2


def test_input_errors():
    rng = np.random.default_rng(6)
    T = turntable(rng, n=6)
    edges, _ = measure(T, ring_pairs(6, hops=(1, 2)), rng)
    E = edges[0][2]
    with pytest.raises(InputError, match="n must be"):
        synchronise(1, edges)
    with pytest.raises(InputError, match=r"edge 0 joins views \(0, 9\)"):
        synchronise(6, [(0, 9, E)] + edges[1:])
    with pytest.raises(InputError, match=r"joins views \(2, 2\)"):
        synchronise(6, edges + [(2, 2, np.eye(4))])
    with pytest.raises(InputError, match=r"edges 0 and 12 both join views \(0, 1\)"):
        synchronise(6, edges + [(1, 0, invert_T(E))])
    with pytest.raises(InputError, match="not a rotation"):
        synchronise(6, [(0, 1, make_T(2 * np.eye(3)))] + edges[1:])
    with pytest.raises(InputError, match=r"\(4, 4\)"):
        synchronise(6, [(0, 1, np.eye(3))] + edges[1:])
    with pytest.raises(InputError, match="weights must be 12"):
        synchronise(6, edges, weights=np.ones(5))
    with pytest.raises(InputError, match="R_world must be"):
        synchronise_translations(6, edges, np.eye(3))
    # Views 6 and 7 only see each other.
    with pytest.raises(InputError, match=r"views \[6, 7\] are not connected to view 0"):
        synchronise(8, edges + [(6, 7, E)])


def test_rejection_that_disconnects_a_view_is_an_error():
    """View 8 hangs on two edges that contradict each other: both are rejected, so view 8 is lost."""
    rng = np.random.default_rng(7)
    T = turntable(rng, n=9)
    pairs = ring_pairs(8) + [(0, 8), (4, 8)]
    edges, _ = measure(T, pairs, rng, rot_noise=np.radians(0.01))
    i, j, T_ij = edges[-1]
    edges[-1] = (i, j, T_ij @ make_T(axis_angle_to_R([1, 0, 0], np.radians(60))))
    with pytest.raises(EdgesDisagree, match=r"views \[8\] are no longer connected to view 0 by edges that a cycle confirms") as info:
        synchronise(9, edges)
    assert info.value.views == [8] and isinstance(info.value, RegistrationError)
    assert synchronise(9, edges, robust=False).inlier.all()
