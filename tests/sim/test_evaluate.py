"""The simulator's mesh accuracy figures against meshes whose error is known exactly."""

import numpy as np
import pytest

from rangekit.surface.mesh import TriangleMesh
from rangekit.sim import default_rig, default_scene
from rangekit.sim.truth.evaluate import mesh_accuracy, sample_surface, visible_samples

ANGLES = np.radians(np.arange(0, 360, 30))


@pytest.fixture(scope="module")
def sphere_setup():
    scene = default_scene("sphere")
    obj = scene.objects[0]
    truth = TriangleMesh(obj.world_vertices(), obj.triangles)
    return scene, default_rig(), truth


def _offset(mesh: TriangleMesh, d: float) -> TriangleMesh:
    """The mesh moved ``d`` metres along its (outward) vertex normals."""
    F, V = mesh.triangles, mesh.vertices
    fn = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    vn = np.zeros_like(V)
    for k in range(3):
        np.add.at(vn, F[:, k], fn)
    vn /= np.linalg.norm(vn, axis=1, keepdims=True)
    return TriangleMesh(V + d * vn, F)


def test_sample_surface_is_area_uniform():
    # Two triangles, areas 1 and 3: samples split 1:3, and every sample lies in its triangle's plane.
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 2, 0], [0, 0, 1], [3, 0, 1], [0, 2, 1]], float)
    F = np.array([[0, 1, 2], [3, 4, 5]])
    P, face = sample_surface(V, F, 200_000, np.random.default_rng(0))
    assert abs(np.mean(face == 1) - 0.75) < 0.005
    assert np.allclose(P[face == 0, 2], 0) and np.allclose(P[face == 1, 2], 1)
    # Uniform inside the triangle: the mean is the centroid.
    assert np.allclose(P[face == 1].mean(axis=0), V[3:].mean(axis=0), atol=0.01)


def test_exact_mesh_scores_zero_and_offsets_score_their_distance(sphere_setup):
    scene, rig, truth = sphere_setup
    exact = mesh_accuracy(truth, scene, rig, ANGLES, n_samples=50_000)
    assert exact.rms < 1e-6 and exact.completeness == 1.0
    # A mesh 0.5 mm outside the truth: every distance is 0.5 mm (up to tessellation sag, ~0.01 mm).
    off = mesh_accuracy(_offset(truth, 5e-4), scene, rig, ANGLES, n_samples=50_000)
    assert abs(off.rms - 5e-4) < 2e-5 and abs(off.p95 - 5e-4) < 2e-5
    assert off.completeness == 1.0
    tight = mesh_accuracy(_offset(truth, 5e-4), scene, rig, ANGLES, tolerance=4e-4, n_samples=50_000)
    assert tight.completeness == 0.0


def test_completeness_counts_the_missing_visible_part(sphere_setup):
    scene, rig, truth = sphere_setup
    # Keep only the triangles with x < 0 (table frame): the visible half with x > 0 is missing.
    centroid_x = truth.vertices[truth.triangles].mean(axis=1)[:, 0]
    half = TriangleMesh(truth.vertices, truth.triangles[centroid_x < 0])
    acc = mesh_accuracy(half, scene, rig, ANGLES, n_samples=60_000)
    P, face = sample_surface(truth.vertices, truth.triangles, 60_000, np.random.default_rng(1))
    seen = visible_samples(truth, scene, rig, ANGLES, P, face, min_cos=np.cos(np.radians(80)))
    seen &= P[:, 2] > 0.002
    expected = np.mean(P[seen, 0] < 0)
    assert abs(acc.completeness - expected) < 0.02
    assert acc.rms < 1e-6  # what is there is exact


def test_visibility_matches_the_ray_cast_ground_truth(sphere_setup):
    # A sample the evaluation calls visible in one view is a pixel the simulator's ground truth calls lit.
    from rangekit.sim import SimRig

    scene, rig, truth = sphere_setup
    P, face = sample_surface(truth.vertices, truth.triangles, 40_000, np.random.default_rng(2))
    seen = visible_samples(truth, scene, rig, [0.0], P, face, min_cos=0.1)
    gt = SimRig(scene, rig).ground_truth()
    uv = np.rint(rig.camera.project(P[seen])).astype(int)
    lit = gt.lit[uv[:, 1], uv[:, 0]] & (gt.object_id[uv[:, 1], uv[:, 0]] == 0)
    assert seen.sum() > 5000 and lit.mean() > 0.995


def test_within_answers_as_the_closest_point_query(sphere_setup):
    """The completeness's k-d tree shortcut (_within) says "within the tolerance" exactly where Open3D's closest-point
    distance does: points from on the surface to twice the tolerance off it, many within a micrometre of the
    tolerance either side, and a vertex no triangle uses (which must not count as surface) at a far point."""
    from rangekit.sim.truth.evaluate import _closest_on, _within

    _, _, truth = sphere_setup
    rng = np.random.default_rng(3)
    P, face = sample_surface(truth.vertices, truth.triangles, 20_000, rng)
    a, b, c = (truth.vertices[truth.triangles[face, k]] for k in range(3))
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    tol = 1e-3
    off = np.concatenate([rng.uniform(0, 2 * tol, 10_000), tol + rng.uniform(-2e-6, 2e-6, 10_000)])
    Q = P + off[:, None] * n * rng.choice([-1.0, 1.0], size=(len(P), 1))
    far = truth.vertices.max(axis=0) + [0.05, 0.0, 0.0]
    mesh = TriangleMesh(np.vstack([truth.vertices, far]), truth.triangles)    # the last vertex is no triangle's
    Q = np.vstack([Q, far + [1e-4, 0.0, 0.0]])
    expected = _closest_on(mesh, Q)[0] <= tol
    got = _within(mesh, Q, tol)
    assert np.array_equal(got, expected)
    assert 0.3 < expected.mean() < 0.8 and not got[-1]
