"""Localisation from bearings (issue 38 item 4): positions against the exact truth, the sign fixed by the
bearings, the parallel-rigidity test naming the nodes bearings do not fix, agreement with the book's toolkit,
and when it beats translation synchronisation (and when not)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from rangekit.errors import InputError, RegistrationError
from support.bearing_networks import compare_with_translation_sync, network
from rangekit.registration import localisability, locate_from_bearings

DATA = Path(__file__).resolve().parents[1] / "fixtures"


def _normalised(c: np.ndarray) -> np.ndarray:
    c = c - c[0]
    return c / np.linalg.norm(c)


@pytest.mark.parametrize("n, p, seed", [(4, 1.0, 0), (15, 0.4, 1), (60, 0.15, 2)])
def test_exact_bearings_give_the_true_positions(n, p, seed):
    c, edges, u = network(n, p, seed)
    located = locate_from_bearings(u, edges)
    assert np.abs(located.positions - _normalised(c)).max() < 1e-12
    assert located.edge_angle_error.max() < 1e-6 and located.singular_values[0] < 1e-12 < located.singular_values[1]


def test_the_sign_comes_from_the_bearings():
    c, edges, u = network(10, 0.5, 3)
    assert np.abs(locate_from_bearings(-u, edges).positions + _normalised(c)).max() < 1e-12     # mirrored truth
    # Edges given the other way round with their bearings reversed: the same network.
    assert np.abs(locate_from_bearings(-u, edges[:, ::-1]).positions - _normalised(c)).max() < 1e-12


@pytest.mark.parametrize("n, edges, not_fixed", [
    (5, [(0, 1), (1, 2), (0, 2), (2, 3), (3, 4), (2, 4)], (3, 4)),            # two triangles sharing node 2
    (4, [(0, 1), (1, 2), (0, 2), (2, 3)], (3,)),                               # a node on one bearing
    (6, [(0, 1), (1, 2), (0, 2), (3, 4), (4, 5), (3, 5)], (3, 4, 5)),          # two separate triangles
    (5, [(0, 1), (1, 2), (0, 2), (2, 3), (1, 3)], (4,)),                       # node 4 has no bearing at all
    (5, [(0, 1), (1, 2), (0, 2), (0, 3), (1, 4), (3, 4)], ()),                 # 3 and 4 fixed only together
    (4, [(0, 1), (1, 2), (2, 3), (3, 0)], ()),                                 # a 4-cycle (in 3D: rigid)
])
def test_localisability_names_the_nodes_bearings_do_not_fix(n, edges, not_fixed):
    test = localisability(n, edges)
    assert test.not_fixed == not_fixed and test.localisable == (not not_fixed)
    assert sorted(test.fixed + test.not_fixed) == list(range(n))


def test_bad_inputs_are_one_line():
    c, edges, u = network(6, 0.6, 4)
    bad = u.copy()
    bad[2, 1] = np.nan
    with pytest.raises(InputError, match=r"^bearings: row 2 is \[.*nan.*\]; expected finite numbers"):
        locate_from_bearings(bad, edges)
    with pytest.raises(InputError, match=r"^bearings: expected an \(m, 3\) array"):
        locate_from_bearings(u[:, :2], edges)
    with pytest.raises(InputError, match=r"^edges: edge 0 joins node 1 to itself"):
        locate_from_bearings(u[:1], [(1, 1)])
    with pytest.raises(RegistrationError, match=r"^bearings: node\(s\) 3, 4 not fixed by the bearings"):
        locate_from_bearings(np.eye(3)[[0, 1, 2, 0, 1, 2]], [(0, 1), (1, 2), (0, 2), (2, 3), (3, 4), (2, 4)])


def test_the_books_toolkit_gives_the_same_positions():
    """tests/fixtures/bearings_toolkit.json: noisy bearings on a 12-node graph and the positions the book's toolkit
    (its cop_from_bearings, run in GNU Octave 7.3 on these inputs; how in the file's 'how') computed."""
    data = json.loads((DATA / "bearings_toolkit.json").read_text())
    U, B = np.array(data["U"]), np.array(data["B"])          # (3, m) bearings, (n, m) incidence (-1 at i, +1 at j)
    edges = np.column_stack([np.argmax(B == -1, axis=0), np.argmax(B == 1, axis=0)])
    ours = locate_from_bearings(U.T, edges).positions
    assert np.abs(ours - np.array(data["C"]).T).max() < 1e-9


def test_bearings_win_when_lengths_are_poor_and_lose_when_they_are_good():
    bearing_err, sync_err = compare_with_translation_sync(1.0, 0.3)        # 1 deg, lengths +-30%
    assert bearing_err < 0.7 * sync_err, (bearing_err, sync_err)
    bearing_err, sync_err = compare_with_translation_sync(1.0, 0.0)        # 1 deg, exact lengths
    assert sync_err < 0.9 * bearing_err, (bearing_err, sync_err)
