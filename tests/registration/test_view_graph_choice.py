"""The view graph's candidate pairs: O(n k) with a prior (nearest in rotation + long links) and
without (a global descriptor, widened until the accepted edges connect the views)."""

import numpy as np
import pytest

from rangekit.errors import InputError, RegistrationError
from rangekit.geometry import axis_angle_to_R, make_T
from rangekit.registration.coarse.graph import (Components, coarse_graph, descriptor_distances, similar_pairs,
                                                view_descriptor)
from rangekit.registration.pairs import (LONG_LINKS, PRIOR_NEIGHBOURS, _rotation_gaps, default_pairs, long_links,
                                         nearest_and_long_links, nearest_in_rotation)


def ring(n: int, axis=(0.0, 0.0, 1.0)) -> np.ndarray:
    """(n, 4, 4) poses turned by 360/n degrees about ``axis`` (a turntable)."""
    return np.stack([make_T(axis_angle_to_R(np.asarray(axis), 2 * np.pi * k / n)) for k in range(n)])


@pytest.mark.parametrize("n", [12, 36, 72])
def test_candidate_count_is_linear_in_views(n):
    T = ring(n)
    pairs = default_pairs(T, False)
    k = PRIOR_NEIGHBOURS
    assert len(pairs) <= n * k // 2 + LONG_LINKS          # 72 views: 148 pairs, not 2,556
    assert len(set(pairs)) == len(pairs) and all(i < j for i, j in pairs)
    near = set(nearest_in_rotation(k)(T, True))
    assert near <= set(pairs) and len(near) == n * k // 2  # a ring: k / 2 on either side
    assert all(min(j - i, n - (j - i)) <= k // 2 for i, j in near)
    links = set(pairs) - near
    assert 1 <= len(links) <= LONG_LINKS
    gaps = np.degrees(_rotation_gaps(T))
    # each long link joins views about 90 deg apart (the nearest the ring's step allows)
    assert all(abs(gaps[i, j] - 90) <= 360 / n / 2 + 1e-9 for i, j in links)
    assert default_pairs(T, False) == pairs                # no prior: nearest + long links
    assert default_pairs(T, True) == sorted(near)          # the turntable's model stops drift: no links
    assert nearest_and_long_links(2, 0)(T) == nearest_in_rotation(2)(T)


def test_long_links_are_distinct_and_far():
    T = ring(12)
    links = long_links(T, 4)
    # anchors 0, 3, 6, 9; view 3 is 90 deg from view 0 and 6, so its link is to 6 (0-3 is taken)
    assert links == [(0, 3), (3, 6), (6, 9), (0, 9)] or links == sorted([(0, 3), (3, 6), (6, 9), (0, 9)])
    assert long_links(T[:2], 4) == [] and long_links(T, 0) == []
    with pytest.raises(InputError, match="links must be an integer >= 0, found -1"):
        nearest_and_long_links(4, -1)


def _two_clusters(n=10):
    """Descriptor distances that split a ring of n views into two halves: within a half every view looks
    alike (distance 1 plus a tie-break), across the halves 10. Only ring neighbours overlap."""
    half = np.arange(n) < n // 2
    d = np.where(half[:, None] == half[None, :], 1.0, 10.0) + 1e-3 * np.abs(np.subtract.outer(range(n), range(n)))
    np.fill_diagonal(d, np.inf)
    return d


class _Edge:
    def __init__(self, i, j, accepted):
        self.i, self.j, self.accepted = i, j, accepted


def test_coarse_graph_repairs_a_graph_the_descriptor_splits():
    n = 10
    dist = _two_clusters(n)
    first = similar_pairs(dist, 2)
    assert all((i < n // 2) == (j < n // 2) for i, j in first)   # the descriptor alone never crosses

    def align(i, j):   # only ring neighbours register
        return _Edge(i, j, min(j - i, n - (j - i)) == 1)

    out = coarse_graph(dist, 2, align)
    comp = Components(n)
    for e in out:
        if e.accepted:
            comp.join(e.i, e.j)
    assert comp.count() == 1                                      # connected through 4-5 or 0-9
    assert any(e.accepted and (e.i < n // 2) != (e.j < n // 2) for e in out)
    assert len(out) < n * (n - 1) // 2                            # without trying every pair
    assert len({(e.i, e.j) for e in out}) == len(out)             # no pair twice


def test_coarse_graph_stops_when_exhausted():
    n = 8
    dist = _two_clusters(n)
    out = coarse_graph(dist, 2, lambda i, j: _Edge(i, j, (i < n // 2) == (j < n // 2)))
    # no cross pair registers: every cross pair is tried once, then it gives up (the caller reports)
    cross = {(e.i, e.j) for e in out if (e.i < n // 2) != (e.j < n // 2)}
    assert len(cross) == (n // 2) ** 2 and len({(e.i, e.j) for e in out}) == len(out)
    with pytest.raises(InputError, match="k must be an integer >= 1, found 0"):
        similar_pairs(dist, 0)


def test_descriptor_is_a_normalised_histogram():
    rng = np.random.default_rng(0)
    f = rng.random((100, 33))
    d = view_descriptor(f)
    assert d.shape == (33,) and np.isclose(d.sum(), 1.0)
    D = descriptor_distances(np.stack([d, d, view_descriptor(f ** 4)]))
    assert D[0, 1] == 0 and D[0, 2] > 0 and np.isinf(D[0, 0]) and np.allclose(D, D.T)


@pytest.fixture(scope="module")
def scans6():
    from rangekit.sim.writers.scans import turntable_scans

    return turntable_scans(n_views=6, noise=0.0005, resolution=(320, 240), rng=0)


@pytest.mark.slow
def test_descriptor_chooser_registers_views_cut_from_one_object(scans6):
    """No prior: coarse alignment of each view with its 4 most similar only, the poses within 0.2 deg and
    0.1% of the diagonal of the simulator's (a wrong pair, a flip or a neighbour's pose, is degrees off)."""
    from rangekit.registration.coarse import CoarseOptions, compute_features
    from rangekit.registration.multiview import register_views
    from rangekit.surface.cloud import bbox_diagonal

    scans = scans6
    n = len(scans.clouds)
    copt = CoarseOptions(voxel=bbox_diagonal(scans.clouds) / 110)
    dist = descriptor_distances(np.stack([view_descriptor(compute_features(c, copt).fpfh) for c in scans.clouds]))
    similar = np.argsort(dist, axis=1)[:, :4]
    # each view's 4 most similar include a neighbour on the turntable (60 deg away); the mean FPFH is a
    # weak descriptor on this object (8 views: 13 of its 19 pairs within 90 deg, against 16 of 28 at random), so
    # the wrong candidates are refused by the coarse RMSE gate and the poses below are what counts
    assert all(any(min((j - i) % n, (i - j) % n) == 1 for j in similar[i]) for i in range(n))
    lines = []
    res = register_views(scans.clouds, progress=lines.append)
    rot = np.array([np.degrees(np.arccos(np.clip((np.trace(a[:3, :3] @ b[:3, :3].T) - 1) / 2, -1, 1)))
                    for a, b in zip(res.T_world_view, scans.T_world_view)])
    tr = np.linalg.norm(res.T_world_view[:, :3, 3] - scans.T_world_view[:, :3, 3], axis=1)
    assert rot.max() < 0.2 and tr.max() < 1e-3 * scans.diag
    tried = res.pairs
    assert tried.coarse < n * (n - 1) // 2   # (6 views: the 8 most overlapping are every pair after it)
    assert any(line.startswith(f"view graph: {tried.tried} of {n * (n - 1) // 2} pairs tried") for line in lines)
    # synchronisation and the joint refinement use the chosen candidates only
    assert len(res.edges) == tried.refined <= tried.candidates and tried.joint <= tried.candidates


@pytest.mark.slow
def test_register_cli_prints_the_pairs_tried(scans6, tmp_path, capsys):
    from rangekit.cli.run import main
    from rangekit.formats.clouds import save_cloud

    files = []
    for k, c in enumerate(scans6.clouds[:4]):
        files.append(str(tmp_path / f"v{k}.ply"))
        save_cloud(files[-1], c)
    assert main(["register", *files, "--no-mesh", "--neighbours", "2", "--out", str(tmp_path / "r")]) == 0
    out = capsys.readouterr().out
    assert "view graph: " in out and " of 6 pairs tried (coarse: " in out and "k=2 nearest + 4 long links" in out
    with pytest.raises(SystemExit) as exc:   # argparse: exit 2
        main(["register", *files, "--no-mesh", "--neighbours", "-1", "--out", str(tmp_path / "r2")])
    assert exc.value.code == 2
    assert "--neighbours" in capsys.readouterr().err


def test_a_view_no_pair_reaches_is_named():
    rng = np.random.default_rng(0)
    from rangekit.registration.multiview import register_views
    from rangekit.surface.cloud import PointCloud

    blob = PointCloud(rng.normal(size=(500, 3)) * 0.01)
    with pytest.raises(RegistrationError, match=r"do not all overlap: views \[\[1\]\]"):
        register_views([blob, PointCloud(blob.points + [5.0, 0, 0])], init_T_world_view=np.stack([np.eye(4)] * 2))


def test_overlap_estimate_counts_shared_cells():
    from rangekit.registration.overlap_estimate import estimated_overlap, overlapping_pairs

    g = np.stack(np.meshgrid(np.arange(10), np.arange(10), [0], indexing="ij"), -1).reshape(-1, 3) + 0.5
    a, b, far = g * 0.01, (g + [5, 0, 0]) * 0.01, (g + [50, 0, 0]) * 0.01   # b shares half of a's cells
    ov = estimated_overlap([a, b, far], 0.01)
    assert np.allclose(ov, [[0, 0.5, 0], [0.5, 0, 0], [0, 0, 0]])
    assert overlapping_pairs([a, b, far], 0.01, 1, 0.15) == [(0, 1)]
    # a ring of 72 views: at most n m pairs, each view with its overlapping neighbours only
    ring72 = [(g + [3 * k, 0, 0]) * 0.01 for k in range(72)]
    pairs = overlapping_pairs(ring72, 0.01, 8, 0.15)
    assert len(pairs) <= 72 * 8 // 2 and all(j - i <= 3 for i, j in pairs)
