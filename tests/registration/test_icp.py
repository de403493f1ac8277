"""ICP and coarse alignment against exact transforms."""

import numpy as np
import pytest
import trimesh

from rangekit.errors import InputError, RegistrationError
from rangekit.geometry import apply_T, axis_angle_to_R, invert_T, make_T, rotation_angle
from rangekit.surface.cloud import PointCloud
from rangekit.registration.coarse import CoarseOptions, coarse_align
from rangekit.registration.icp import KERNELS, IcpOptions, OrganisedScan, icp
from rangekit.sim.scene.objects import lumpy
from rangekit.sim.writers.scans import turntable_scans


@pytest.fixture(scope="module")
def surface():
    tm = lumpy().to_trimesh()
    a, fa = trimesh.sample.sample_surface(tm, 60000, seed=1)
    b, fb = trimesh.sample.sample_surface(tm, 60000, seed=2)
    return a, tm.face_normals[fa], b, tm.face_normals[fb]


def moved(T, pts, nrm):
    """Source = target surface moved by inv(T): registering it back must give T."""
    return PointCloud(apply_T(invert_T(T), pts), normals=nrm @ T[:3, :3])


def errors(T_est, T_true):
    return np.degrees(rotation_angle(T_est[:3, :3] @ T_true[:3, :3].T)), np.linalg.norm(T_est[:3, 3] - T_true[:3, 3])


T_5 = make_T(axis_angle_to_R([0.3, 1, 0.2], np.radians(5)), [0.004, 0.002, -0.001])


@pytest.mark.parametrize("method", ["point_to_plane", "point_to_point", "symmetric"])
def test_icp_recovers_an_exact_transform(surface, method):
    a, na, b, nb = surface
    if method == "point_to_point":  # biased between different samplings of a surface: use the same points
        b, nb = a, na
    res = icp(moved(T_5, b, nb), PointCloud(a, normals=na),
              options=IcpOptions(method=method, max_distance=0.01, max_iterations=300))
    rot, tr = errors(res.T_target_source, T_5)
    print(f"\n{method}: {res}")
    assert rot < 1e-4 and tr < 1e-6
    assert res.converged and res.fitness > 0.99


@pytest.mark.parametrize("kernel", [k for k in KERNELS if k != "none"])
def test_robust_kernels_ignore_outliers(surface, kernel):
    a, na, b, nb = surface
    rng = np.random.default_rng(3)
    src = moved(T_5, b, nb)
    junk = rng.uniform(src.points.min(0), src.points.max(0), size=(15000, 3))  # 20% outliers
    jn = rng.normal(size=(15000, 3))
    src = PointCloud(np.r_[src.points, junk], normals=np.r_[src.normals, jn / np.linalg.norm(jn, axis=1, keepdims=True)])
    res = icp(src, PointCloud(a, normals=na), options=IcpOptions(kernel=kernel, max_distance=0.01, max_iterations=100))
    rot, tr = errors(res.T_target_source, T_5)
    # The simulator's normal maps are shading normals (interpolated over the flat facets), which biases
    # point-to-plane by about 0.01 deg here; the KD-tree tests above use exact facet normals.
    assert rot < 0.02 and tr < 2e-5, (kernel, rot, tr)


def test_trimming_handles_partial_overlap(surface):
    a, na, b, nb = surface
    keep_src = b[:, 0] > np.percentile(b[:, 0], 30)   # the source sees 70% of the object
    keep_tgt = a[:, 0] < np.percentile(a[:, 0], 80)   # the target another 80%
    res = icp(moved(T_5, b[keep_src], nb[keep_src]), PointCloud(a[keep_tgt], normals=na[keep_tgt]),
              options=IcpOptions(trim=0.2, max_distance=0.01, max_iterations=100))
    rot, tr = errors(res.T_target_source, T_5)
    assert rot < 5e-3 and tr < 5e-5


def test_voxel_schedule_converges_from_far(surface):
    a, na, b, nb = surface
    T = make_T(axis_angle_to_R([1, 0.2, 0.4], np.radians(20)), [0.01, -0.008, 0.004])
    plain = icp(moved(T, b, nb), PointCloud(a, normals=na), options=IcpOptions(max_distance=0.004))
    sched = icp(moved(T, b, nb), PointCloud(a, normals=na),
                options=IcpOptions(max_distance=0.004, voxel_sizes=(0.012, 0.006)))
    assert errors(sched.T_target_source, T)[0] < 1e-4 and sched.converged
    assert errors(plain.T_target_source, T)[0] < 1e-4


def test_projective_association_on_organised_scans():
    scans = turntable_scans(n_views=12, noise=0.0, resolution=(640, 512))
    cam = scans.rig.camera
    # View 1 registered onto view 0 by projecting into view 0's range map (its frame = the rig world).
    T_true = invert_T(scans.T_world_view[0]) @ scans.T_world_view[1]
    init = make_T(axis_angle_to_R([0, 0.2, 1], np.radians(2)), [0.002, 0, 0]) @ T_true
    target = OrganisedScan(scans.range_maps[0], scans.normal_maps[0], cam)
    res = icp(scans.clouds[1], None, init_T_target_source=init, target_scan=target,
              options=IcpOptions(max_distance=0.005, max_iterations=100))
    rot, tr = errors(res.T_target_source, T_true)
    print(f"\nprojective: {res}; error {rot:.2e} deg, {tr * 1e3:.4f} mm")
    # The simulator's normal maps are shading normals (interpolated over the flat facets), which biases
    # point-to-plane by about 0.01 deg here; the KD-tree tests above use exact facet normals.
    assert rot < 0.02 and tr < 2e-5


@pytest.mark.slow
def test_coarse_alignment_without_a_guess(surface):
    a, na, b, nb = surface
    T = make_T(axis_angle_to_R([0.2, -1, 0.5], np.radians(120)), [0.05, -0.02, 0.03])
    opt = CoarseOptions(voxel=0.004, rng=0)
    r1 = coarse_align(moved(T, b, nb), PointCloud(a, normals=na), opt)
    r2 = coarse_align(moved(T, b, nb), PointCloud(a, normals=na), opt)
    assert np.array_equal(r1.T_target_source, r2.T_target_source)  # deterministic for a seed
    rot, tr = errors(r1.T_target_source, T)
    assert rot < 0.05 and tr < 2e-4


def test_icp_bad_input():
    with pytest.raises(RegistrationError, match="at least 3"):
        icp(np.zeros((2, 3)), np.random.default_rng(0).random((100, 3)))
    with pytest.raises(RegistrationError, match="normals"):
        icp(np.random.default_rng(0).random((100, 3)), np.random.default_rng(1).random((100, 3)))
    far = icp(np.random.default_rng(0).random((100, 3)) + 10, np.random.default_rng(1).random((100, 3)),
              options=IcpOptions(method="point_to_point"))
    assert not far.converged and "degenerate" in far.reason
    with pytest.raises(InputError, match="kernel"):
        IcpOptions(kernel="bisquare")


@pytest.mark.parametrize("method", ["point_to_plane", "point_to_point"])
def test_singular_system_is_not_reported_as_converged(surface, method):
    # Tukey weights are 0 beyond 4.7 kernel scales: with a 1 nm scale and a 5 deg offset no
    # correspondence keeps any weight, so the normal equations are all zeros and there is no update.
    a, na, b, nb = surface
    res = icp(moved(T_5, b, nb), PointCloud(a, normals=na),
              options=IcpOptions(method=method, kernel="tukey", kernel_scale=1e-9, max_distance=0.01))
    assert not res.converged
    assert "singular" in res.reason and "0 of" in res.reason
    assert res.n_iterations == 1
    assert np.array_equal(res.T_target_source, np.eye(4))  # no step taken, and it says so


def test_voxel_downsample_returns_a_pair_whatever_its_flags():
    from rangekit.surface.cloud import voxel_downsample

    rng = np.random.default_rng(0)
    P = rng.uniform(0, 0.01, (1000, 3))
    N = rng.normal(size=(1000, 3))
    for voxel in (0.002, 0.0):
        p, n = voxel_downsample(P, voxel)
        assert p.shape[1] == 3 and n is None
        p2, n2 = voxel_downsample(P, voxel, normals=N)
        assert np.array_equal(p, p2) and n2.shape == p2.shape
    assert len(voxel_downsample(P, 0.002)[0]) < len(P)


def test_icp_does_not_match_the_back_face_of_a_thin_part():
    """A fin 1.5 mm thick whose target view saw the front face (normal +z) on one half and only the back
    face (normal -z) on the other, both within the 2 mm gate of a source view of the whole front face.
    Correspondences whose normals differ by more than 60 degrees do not count, so the source stays on
    the front face; without source normals the back face pulls it off."""
    rng = np.random.default_rng(0)
    x, y = rng.uniform(-0.01, 0.01, size=(2, 6000))
    # Bumps (0.3 mm, 10 mm period) so that every motion is constrained; normals exact.
    k, a = 2 * np.pi / 0.01, 0.3e-3
    z = a * np.sin(k * x) * np.sin(k * y)
    up = np.column_stack([-a * k * np.cos(k * x) * np.sin(k * y), -a * k * np.sin(k * x) * np.cos(k * y),
                          np.ones_like(x)])
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    front = np.column_stack([x, y, z])
    seen = x < 0   # the target view saw the front face here, only the back face elsewhere
    target = PointCloud(np.where(seen[:, None], front, front - [0.0, 0.0, 1.5e-3]),
                        normals=np.where(seen[:, None], up, -up))
    source = front + rng.normal(scale=2e-4, size=(len(x), 3)) * [1, 1, 0]   # other samples of the surface
    source[:, 2] = a * np.sin(k * source[:, 0]) * np.sin(k * source[:, 1])
    n_src = np.column_stack([-a * k * np.cos(k * source[:, 0]) * np.sin(k * source[:, 1]),
                             -a * k * np.sin(k * source[:, 0]) * np.cos(k * source[:, 1]), np.ones(len(x))])
    n_src /= np.linalg.norm(n_src, axis=1, keepdims=True)
    opt = IcpOptions(method="point_to_plane", kernel="none", max_distance=2e-3, max_iterations=30)
    r = icp(PointCloud(source, normals=n_src), target, options=opt)
    assert np.linalg.norm(r.T_target_source[:3, 3]) < 2e-5 and rotation_angle(r.T_target_source[:3, :3]) < 3e-4
    r = icp(PointCloud(source), target, options=opt)
    assert np.linalg.norm(r.T_target_source[:3, 3]) > 2e-4, r.T_target_source[:3, 3]
