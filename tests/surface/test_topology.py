"""rangekit.surface.topology against exact oracles: unique_rows against the lexsort definition, and
is_closed_manifold against trimesh's is_watertight and is_winding_consistent (after merge_vertices)."""

import numpy as np
import pytest
import trimesh

from rangekit.surface.topology import is_closed_manifold, unique_rows


def _unique_rows_lexsort(a):
    """The definition: distinct rows numbered by first occurrence (the former lexsort implementation)."""
    seen, first, inverse = {}, [], []
    for i, row in enumerate(map(tuple, a)):
        if row not in seen:
            seen[row] = len(first)
            first.append(i)
        inverse.append(seen[row])
    return np.array(first), np.array(inverse)


@pytest.mark.parametrize("high", [3, 1000, 2 ** 40, 2 ** 62])   # packed, and ranked when too wide to pack
def test_unique_rows_matches_first_occurrence_definition(high):
    rng = np.random.default_rng(high % 1000)
    base = rng.integers(-high, high, size=(60, 3))
    a = base[rng.integers(0, 60, 500)]                # many repeats
    first, inverse = unique_rows(a)
    ref_first, ref_inverse = _unique_rows_lexsort(a)
    assert np.array_equal(first, ref_first) and np.array_equal(inverse, ref_inverse)


def _trimesh_closed(V, F):
    tm = trimesh.Trimesh(vertices=V, faces=F, process=False)
    tm.merge_vertices()
    return bool(tm.is_watertight and tm.is_winding_consistent)


def _cases():
    box = trimesh.creation.box()
    V, F = np.asarray(box.vertices), np.asarray(box.faces, dtype=np.int64)
    sphere = trimesh.creation.icosphere(subdivisions=2)
    Vs, Fs = np.asarray(sphere.vertices) * 0.05, np.asarray(sphere.faces, dtype=np.int64)
    split = np.concatenate([Vs, Vs[:10]])             # exact duplicates: merged, still closed
    Fsplit = Fs.copy()
    Fsplit[:40][Fsplit[:40] < 10] += len(Vs)
    flipped = Fs.copy()
    flipped[0] = flipped[0, ::-1]                     # one face wound the other way
    return {"box": (V, F, True), "sphere": (Vs, Fs, True), "open": (Vs, Fs[1:], False),
            "merged duplicates": (split, Fsplit, True), "far duplicates": (np.concatenate([Vs, Vs[:10] + 1e-6]),
                                                                         Fsplit, False),
            "flipped": (Vs, flipped, False), "doubled face": (Vs, np.concatenate([Fs, Fs[:1]]), False),
            "two spheres": (np.concatenate([Vs, Vs + 1]), np.concatenate([Fs, Fs + len(Vs)]), True),
            "unreferenced vertex": (np.concatenate([Vs, [[9.0, 9, 9]]]), Fs, True)}


@pytest.mark.parametrize("name", list(_cases()))
def test_is_closed_manifold_matches_trimesh(name):
    V, F, expected = _cases()[name]
    assert _trimesh_closed(V, F) is expected
    assert is_closed_manifold(V, F) is expected


def test_is_closed_manifold_of_no_triangles_is_false():
    assert is_closed_manifold(np.zeros((3, 3)), np.zeros((0, 3), np.int64)) is False


def _fan_count_scipy(F, n_vertices):
    """The definition: connected groups of corners of one vertex, linked across interior edges (scipy)."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    corners = [(f, k) for f in range(len(F)) for k in range(3)]
    index = {c: i for i, c in enumerate(corners)}
    by_edge = {}
    for f in range(len(F)):
        for k in range(3):
            by_edge.setdefault(frozenset((F[f, k], F[f, (k + 1) % 3])), []).append((f, k))
    rows, cols = [], []
    for faces in by_edge.values():
        if len(faces) == 2:
            (f1, k1), (f2, _) = faces
            for v in (F[f1, k1], F[f1, (k1 + 1) % 3]):
                rows.append(index[(f1, list(F[f1]).index(v))])
                cols.append(index[(f2, list(F[f2]).index(v))])
    G = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(corners), len(corners)))
    _, label = connected_components(G, directed=False)
    fan_vertex = {}
    for (f, k), lab in zip(corners, label):
        fan_vertex[lab] = F[f, k]
    return np.bincount(list(fan_vertex.values()), minlength=n_vertices)


def test_fan_count_finds_bow_ties_as_the_corner_graph_does():
    from rangekit.surface.watertight import _face_edge_ids, _fan_count

    sphere = trimesh.creation.icosphere(subdivisions=1)
    Fs = np.asarray(sphere.faces, dtype=np.int64)
    n = len(sphere.vertices)
    # Two spheres pinched at one vertex (vertex 0 of both is the same: a bow-tie of two closed fans), one of
    # them with faces removed (open fans), and a lone triangle on vertex 1.
    F2 = Fs + n
    F2[F2 == n] = 0
    F = np.concatenate([Fs, F2[5:], [[1, 2 * n, 2 * n + 1]]])
    fe, n_edges = _face_edge_ids(F, 2 * n + 2)
    counts = np.bincount(fe.ravel(), minlength=n_edges)
    fans = _fan_count(F, fe, counts, 2 * n + 2)
    assert np.array_equal(fans, _fan_count_scipy(F, 2 * n + 2))
    assert fans[0] == 2 and fans[1] == 2 and fans[5] == 1


def test_with_observed_carries_the_watertight_answer():
    from rangekit.surface.mesh import TriangleMesh

    sphere = trimesh.creation.icosphere(subdivisions=1)
    m = TriangleMesh(np.asarray(sphere.vertices), np.asarray(sphere.faces))
    assert m.is_watertight
    flagged = m.with_observed(np.ones(len(m.vertices), bool))
    assert "is_watertight" in flagged.__dict__ and flagged.is_watertight and flagged.observed.all()
