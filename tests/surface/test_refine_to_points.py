"""The observed mesh put back on its input points (rangekit/surface/refine.py, issue 51): a midpoint subdivision of
every edge or of some keeps the mesh one manifold with the same winding and area, and projecting the vertices onto
the points' planes, halving the edges whose surface bows from the chord, takes a coarse mesh's flat triangles back
onto the true surface and leaves a flat part as it was. Against analytic truth: a sphere, a circle, a plane."""

from __future__ import annotations

import numpy as np
import pytest

from rangekit.errors import InputError
from rangekit.surface.mesh import TriangleMesh
from rangekit.surface.refine import (SPLIT_SAG, edge_sag, mesh_edges, project_to_points, refine_to_points,
                                     subdivide_edges, subdivide_midpoint)

R = 0.02   # sphere radius, metres


def _icosahedron() -> TriangleMesh:
    t = (1 + 5 ** 0.5) / 2
    V = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t], [0, 1, -t],
                  [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], dtype=np.float64)
    F = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4], [11, 10, 2],
                  [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9], [4, 9, 5],
                  [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    return TriangleMesh(R * V / np.linalg.norm(V, axis=1, keepdims=True), F)


def _coarse_sphere(levels: int) -> TriangleMesh:
    """An icosphere of radius R whose vertices are on the sphere and whose triangles are chords inside it."""
    mesh = _icosahedron()
    for _ in range(levels):
        fine = subdivide_midpoint(mesh)
        mesh = TriangleMesh(R * fine.vertices / np.linalg.norm(fine.vertices, axis=1, keepdims=True), fine.triangles)
    return mesh


def _sphere_points(n: int, noise: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    phi = np.pi * (1 + 5 ** 0.5) * i
    u = np.column_stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z])
    return R * u + np.random.default_rng(seed).normal(0, noise, (n, 3)), u


def _area_rms(mesh: TriangleMesh, n: int = 100_000) -> float:
    """RMS distance to the sphere of ``n`` area-uniform samples of ``mesh`` (the evaluator's way)."""
    from rangekit.sim.truth.evaluate import sample_surface

    P, _ = sample_surface(mesh.vertices, mesh.triangles, n, np.random.default_rng(1))
    return float(np.sqrt(np.mean((np.linalg.norm(P, axis=1) - R) ** 2)))


def _edges(F: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    return np.unique(e, axis=0, return_counts=True)


def test_subdivision_makes_four_triangles_of_each_one_manifold_same_winding_and_area():
    mesh = _coarse_sphere(1)
    mesh = TriangleMesh(mesh.vertices, mesh.triangles,
                        np.random.default_rng(0).random((len(mesh.vertices), 3)).astype(np.float32))
    fine = subdivide_midpoint(mesh)
    n_edges = len(_edges(mesh.triangles)[0])
    assert len(fine.vertices) == len(mesh.vertices) + n_edges and len(fine.triangles) == 4 * len(mesh.triangles)
    assert np.all(_edges(fine.triangles)[1] == 2)          # still closed: every edge between two triangles
    assert fine.area == pytest.approx(mesh.area, rel=1e-12)
    a, b, c = (fine.vertices[fine.triangles[:, i]] for i in range(3))
    centroid = (a + b + c) / 3
    assert np.all(np.einsum("ij,ij->i", np.cross(b - a, c - a), centroid) > 0)   # outward, as the input
    # A midpoint's colour is its edge ends' mean.
    e = _edges(mesh.triangles)[0]
    assert np.allclose(fine.vertex_colours[len(mesh.vertices):], 0.5 * (mesh.vertex_colours[e[:, 0]]
                                                                       + mesh.vertex_colours[e[:, 1]]))


def test_halving_some_edges_splits_each_triangle_by_its_halved_edges_and_keeps_one_closed_manifold():
    """Each edge halved or not at random: a triangle with 0-3 halved edges becomes 1-4 triangles, the mesh stays
    closed (no edge with a midpoint on one side only), the area and the outward winding are kept."""
    mesh = _coarse_sphere(2)
    edges, edge_of = mesh_edges(mesh.triangles, len(mesh.vertices))
    assert len(edges) == len(_edges(mesh.triangles)[0]) and np.array_equal(edges, _edges(mesh.triangles)[0])
    split = np.random.default_rng(3).random(len(edges)) < 0.4
    fine = subdivide_edges(mesh, split, edges, edge_of)
    per_triangle = split[edge_of].sum(axis=0)                      # 0-3 halved edges a triangle
    assert set(np.unique(per_triangle)) == {0, 1, 2, 3}
    assert len(fine.vertices) == len(mesh.vertices) + split.sum()
    assert len(fine.triangles) == len(mesh.triangles) + per_triangle.sum()
    assert np.all(_edges(fine.triangles)[1] == 2)
    assert fine.area == pytest.approx(mesh.area, rel=1e-12)
    a, b, c = (fine.vertices[fine.triangles[:, i]] for i in range(3))
    assert np.all(np.einsum("ij,ij->i", np.cross(b - a, c - a), (a + b + c) / 3) > 0)
    assert np.allclose(fine.vertices[len(mesh.vertices):], mesh.vertices[edges[split]].mean(axis=1))
    with pytest.raises(InputError, match="split must be"):
        subdivide_edges(mesh, split[1:])


def test_edge_sag_is_the_circle_chords_sagitta():
    """Chords of a circle of radius 20 mm with its radial normals at the ends: the estimate is the sagitta
    R (1 - cos(angle / 2)) within 0.1% for chords up to 2 mm; a straight line's normals give 0."""
    angle = np.array([0.01, 0.05, 0.1])
    P = np.stack([np.zeros(3), angle], 1)                           # (3, 2) the ends' angles
    n = np.stack([np.cos(P), np.sin(P), np.zeros_like(P)], -1).reshape(-1, 3)
    sag = edge_sag(R * n, n, np.arange(6).reshape(3, 2))
    assert np.allclose(sag, R * (1 - np.cos(angle / 2)), rtol=1e-3)
    line = np.array([[0.0, 0, 0], [0.001, 0, 0]])
    assert edge_sag(line, np.tile([0.0, 0, 1], (2, 1)), np.array([[0, 1]]))[0] == 0


def test_a_flat_mesh_is_put_on_its_plane_and_not_subdivided():
    """A coarse grid 0.5 mm above a plane of points: every vertex lands on the plane, no edge is halved."""
    g = np.stack(np.meshgrid(np.linspace(-1, 1, 81), np.linspace(-1, 1, 81)), -1).reshape(-1, 2) * 0.01
    P = np.column_stack([g, np.zeros(len(g))])
    N = np.tile([0.0, 0.0, 1.0], (len(P), 1))
    u = np.linspace(-0.008, 0.008, 9)
    V = np.column_stack([np.stack(np.meshgrid(u, u), -1).reshape(-1, 2), np.full(81, 5e-4)])
    i = np.arange(81).reshape(9, 9)[:-1, :-1].ravel()
    F = np.concatenate([np.stack([i, i + 1, i + 10], 1), np.stack([i, i + 10, i + 9], 1)])
    refined = refine_to_points(TriangleMesh(V, F), P, N)
    assert np.array_equal(refined.triangles, F) and np.allclose(refined.vertices[:, 2], 0, atol=1e-15)
    assert len(refine_to_points(TriangleMesh(V, F), P, N, sag=0).triangles) == 4 * len(F)   # 0: every edge
    with pytest.raises(InputError, match="sag must be >= 0"):
        refine_to_points(TriangleMesh(V, F), P, N, sag=-1e-6)


def test_refined_coarse_sphere_lies_on_the_sphere():
    """A 2 mm-edged icosphere (its chords up to 25 um inside the sphere) refined onto 60k points with 10 um noise:
    the refined mesh's area-sampled RMS (its halved chords' error and the points' noise, averaged) is under half the
    coarse one's (15 um) and under the points' noise."""
    coarse = _coarse_sphere(4)
    P, N = _sphere_points(60_000, 10e-6)
    refined = refine_to_points(coarse, P, N)
    before, after = _area_rms(coarse), _area_rms(refined)
    print(f"\nsphere R 20 mm: coarse {before * 1e6:.1f} um RMS, refined {after * 1e6:.1f} um RMS")
    assert before > 5e-6 and after < before / 2 and after < 10e-6, (before, after)
    assert len(refined.triangles) == 4 * len(coarse.triangles)   # every chord bows 25 um: over SPLIT_SAG
    assert SPLIT_SAG < 25e-6


def test_projection_is_exact_on_a_plane_and_keeps_a_vertex_whose_neighbours_disagree():
    g = np.stack(np.meshgrid(np.linspace(-1, 1, 41), np.linspace(-1, 1, 41)), -1).reshape(-1, 2) * 0.01
    P = np.column_stack([g, np.zeros(len(g))])
    N = np.tile([0.0, 0.0, 1.0], (len(P), 1))
    V = np.array([[0.001, 0.002, 0.0007], [-0.003, 0.0, -0.0004]])
    out = project_to_points(V, P, N)
    assert np.allclose(out[:, 2], 0, atol=1e-15) and np.allclose(out[:, :2], V[:, :2])
    # Two points as near, with opposed normals, give no plane: the vertex is left where it was.
    v = np.array([[0.0, 0.0, 0.0007]])
    two = np.array([[-0.001, 0.0, 0.0], [0.001, 0.0, 0.0]])
    assert np.array_equal(project_to_points(v, two, np.array([[0, 0, 1.0], [0, 0, -1.0]]), k=2), v)


@pytest.mark.parametrize("points, normals, vertices, k, match", [
    (np.zeros((4, 2)), np.zeros((4, 2)), np.zeros((1, 3)), 6, "points and normals must be"),
    (np.zeros((4, 3)), np.zeros((3, 3)), np.zeros((1, 3)), 6, "points and normals must be"),
    (np.zeros((4, 3)), np.zeros((4, 3)), np.zeros((1, 2)), 6, "vertices must be"),
    (np.zeros((4, 3)), np.zeros((4, 3)), np.zeros((1, 3)), 0, "k must be an integer >= 1"),
])
def test_bad_input_is_named(points, normals, vertices, k, match):
    with pytest.raises(InputError, match=match):
        project_to_points(vertices, points, normals, k=k)


def test_the_observed_cuts_query_refines_as_a_query_of_its_own():
    """The observed mesh cut and refined from one k-d tree query (ObservedRule.observed_near, refine_to_points'
    ``near``; issue 51: the fusion's CPU) is the same mesh, to the bit, as the cut and a query of its own; a
    ``near`` of the wrong shape is named."""
    from rangekit.surface.observed import observed_rule

    P, N = _sphere_points(60_000, 10e-6)
    keep = P[:, 2] > -0.5 * R                                # the bottom unobserved: the cut drops vertices
    rule = observed_rule(P[keep])
    coarse = _coarse_sphere(4)
    cut = rule.observed_part(coarse)
    alone = refine_to_points(cut, P[keep], N[keep], tree=rule.tree)
    cut2, d, idx = rule.observed_near(coarse, 6)
    shared = refine_to_points(cut2, P[keep], N[keep], tree=rule.tree, near=(d, idx))
    assert 0 < len(cut.vertices) < len(coarse.vertices)
    np.testing.assert_array_equal(cut2.triangles, cut.triangles)
    np.testing.assert_array_equal(shared.vertices, alone.vertices)
    np.testing.assert_array_equal(shared.triangles, alone.triangles)
    with pytest.raises(InputError, match="near must be"):
        refine_to_points(cut2, P[keep], N[keep], near=(d[:, :3], idx[:, :3]))
