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
