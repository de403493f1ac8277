"""What part of a fused surface the views observed: distance of each vertex to the input points, against
the points' local spacing.

A fusion (Poisson, TSDF) returns a surface also where no view looked: the balloon under an object, the web
Poisson stretches across the gap between two thin parts (the bunny's ears). A vertex is *observed* when an
input point lies within ``factor x`` that point's local spacing of it; everything else is invented.

- :func:`point_spacing`: per point, the mean distance to its ``k`` nearest neighbours (metres).
- :func:`observed_vertices`: (V,) bool, the vertices some input point supports.
- :func:`keep_observed`: the mesh without its unobserved vertices and every triangle touching one.
- :func:`split_observed`: a fusion's two outputs (:class:`FusedMeshes`): the observed surface, and the
  surface closed with a per-vertex ``observed`` flag.
- :func:`observed_rule`: the rule made once for a set of points (:class:`ObservedRule`), to judge a
  fusion's meshes as they come.

Units are metres; the mesh and the points share one frame. Deterministic (scipy's k-d tree, no threads).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from rangekit.errors import InputError
from rangekit.surface.mesh import TriangleMesh

if TYPE_CHECKING:   # scipy.spatial is imported where a tree is built: Poisson's child imports this module, builds none
    from scipy.spatial import cKDTree

__all__ = ["OBSERVED_FACTOR", "SPACING_NEIGHBOURS", "MEDIAN_POINTS", "MAX_SPACING_RATIO", "FusedMeshes", "point_spacing",
           "observed_vertices", "keep_observed", "split_observed",
           "ObservedRule", "observed_rule"]

#: A vertex is observed within this many local point spacings of an input point. A vertex between points
#: on an observed patch is at most about half a spacing from one (plus the noise Poisson smooths away), so
#: 2 keeps the observed surface and a thin band of its rim, and drops a web a few spacings off the data.
#: At the rim Poisson bends away from the truth as it leaves the data: on the 12-view upright bunny, 3
#: spacings kept 40 vertices more than 1 mm from the true surface (under the chin and at the foot), 2
#: spacings none (farthest 0.86 mm) for 0.07% of the vertices within 0.05 mm of the truth.
OBSERVED_FACTOR = 2.0
#: Neighbours whose mean distance is a point's local spacing.
SPACING_NEIGHBOURS = 6
#: Points whose spacing gives the median spacing of a large cloud (every ``N // MEDIAN_POINTS``-th point): the
#: median of 674k points' spacings (the default 12-view session's Poisson input) and of every 10th point's
#: differ by 0.1%, and no other point's spacing is needed but the nearest points' of the meshes judged.
#: Clouds of fewer than twice this take every point (issue 51: the rule's k-d tree queries were 1.2 of
#: the fusion's CPU-s).
MEDIAN_POINTS = 65_536
#: A point's spacing counts at most this many times the median spacing. Isolated points (a sparse row at
#: the foot of an object, seen at grazing angles, without a normal for Poisson) would otherwise make a
#: wide disc observed where Poisson only interpolates: on the 6-view lumpy scan the uncapped rule (with
#: 3 spacings) kept vertices 1.43 mm from the truth; with both at 2 the farthest is 0.31 mm.
MAX_SPACING_RATIO = 2.0


def _points(points, what: str) -> np.ndarray:
    P = np.asarray(points, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise InputError(f"{what}: points must be (N, 3), found shape {P.shape}")
    P = P[np.all(np.isfinite(P), axis=1)]
    if len(P) < 2:
        raise InputError(f"{what}: expected at least 2 finite points, found {len(P)}")
    return P


def point_spacing(points: np.ndarray, *, k: int = SPACING_NEIGHBOURS) -> np.ndarray:
    """(N,) metres: each point's mean distance to its ``k`` nearest other points of ``points`` (N, 3)
    (non-finite rows dropped first: the result is per finite point, in order)."""
    P = _points(points, "point_spacing")
    from scipy.spatial import cKDTree

    return _spacing(cKDTree(P), k)


def _spacing(tree: cKDTree, k: int) -> np.ndarray:
    """:func:`point_spacing` of the (finite) points ``tree`` was built on."""
    k = int(min(k, tree.n - 1))
    d, _ = tree.query(tree.data, k=k + 1)
    return d[:, 1:].mean(axis=1)


def _filled(tree: cKDTree, s: np.ndarray, rows: np.ndarray, k: int, workers: int = 1) -> np.ndarray:
    """``s[rows]``, the points' spacing (:func:`_spacing`), each NaN among them computed once and kept in ``s``
    (the query on ``workers`` threads: each point's its own, the same answers)."""
    missing = np.unique(rows[np.isnan(s[rows])])
    if len(missing):
        k = int(min(k, tree.n - 1))
        d, _ = tree.query(tree.data[missing], k=k + 1, workers=workers)
        s[missing] = d[:, 1:].mean(axis=1)
    return s[rows]


def _within(vertices: np.ndarray, tree: cKDTree, s: np.ndarray, factor: float, median: float,
            k: int = SPACING_NEIGHBOURS) -> np.ndarray:
    """The rule of :func:`observed_vertices` on a tree of the points, their spacing (NaN: not yet computed, then
    computed with ``k`` neighbours and kept) and its median."""
    if len(vertices) == 0:
        return np.zeros(0, dtype=bool)
    d, nearest = tree.query(vertices, k=1)
    return _near_enough(d, nearest, tree, s, factor, median, k)


def _near_enough(d: np.ndarray, nearest: np.ndarray, tree: cKDTree, s: np.ndarray, factor: float, median: float,
                 k: int, workers: int = 1) -> np.ndarray:
    """:func:`_within` given each vertex's nearest point ``nearest`` (V,) and its distance ``d`` (V,)."""
    return d <= factor * np.minimum(_filled(tree, s, nearest, k, workers), MAX_SPACING_RATIO * median)


def observed_vertices(vertices: np.ndarray, points: np.ndarray, *, spacing: np.ndarray | None = None,
                      factor: float = OBSERVED_FACTOR, k: int = SPACING_NEIGHBOURS) -> np.ndarray:
    """(V,) bool: vertex ``v`` of ``vertices`` (V, 3) is observed when its nearest point ``p`` of
    ``points`` (N, 3, finite) lies within ``factor * min(spacing[p], MAX_SPACING_RATIO * median(spacing))``.

    ``spacing`` (N,) metres, per point: its local sampling distance; default :func:`point_spacing` with
    ``k`` neighbours. Give it when the sampling is anisotropic in a way the nearest neighbours do not see
    (a laser scan's profiles: dense along a line, a turntable step apart between lines).
    """
    V = np.asarray(vertices, dtype=np.float64)
    if V.ndim != 2 or V.shape[1] != 3:
        raise InputError(f"observed_vertices: vertices must be (V, 3), found shape {V.shape}")
    return observed_rule(points, spacing=spacing, factor=factor, k=k).flags(V)


def _spaced_tree(points: np.ndarray, spacing: np.ndarray | None, factor: float, k: int) -> tuple[cKDTree, np.ndarray]:
    """A k-d tree of ``points`` and their spacing (given or :func:`point_spacing`), checked as
    :func:`observed_vertices` documents."""
    if not (np.isfinite(factor) and factor > 0):
        raise InputError(f"observed_vertices: factor must be finite and > 0, found {factor!r}")
    P = np.asarray(points, dtype=np.float64)
    if P.ndim == 2 and P.shape[1] == 3 and not np.all(np.isfinite(P)):
        raise InputError(f"observed_vertices: points must be finite, found "
                         f"{np.count_nonzero(~np.isfinite(P).all(axis=1))} rows that are not")
    from scipy.spatial import cKDTree

    tree = cKDTree(_points(P, "observed_vertices"), balanced_tree=False)   # built in half the time, the same answers
    if spacing is None:                # computed where needed (:func:`_filled`): NaN until then
        return tree, np.full(tree.n, np.nan)
    s = np.asarray(spacing, dtype=np.float64)
    if s.shape != (tree.n,) or not np.all(np.isfinite(s) & (s >= 0)):
        raise InputError(f"observed_vertices: spacing must be ({tree.n},) finite and >= 0, found shape {s.shape}")
    return tree, s


def keep_observed(mesh: TriangleMesh, observed: np.ndarray) -> TriangleMesh:
    """``mesh`` without the vertices where ``observed`` (V,) bool is False, nor any triangle touching one;
    unreferenced vertices dropped, order kept. Colours follow their vertices."""
    return _kept(mesh, observed)[0]


def _kept(mesh: TriangleMesh, observed: np.ndarray) -> tuple[TriangleMesh, np.ndarray]:
    """:func:`keep_observed` and which vertices of ``mesh`` it kept ((V,) bool, their order kept)."""
    observed = np.asarray(observed, dtype=bool)
    if observed.shape != (len(mesh.vertices),):
        raise InputError(f"keep_observed: observed must be ({len(mesh.vertices)},) bool, found shape {observed.shape}")
    F = mesh.triangles[np.all(observed[mesh.triangles], axis=1)]
    used = np.zeros(len(mesh.vertices), dtype=bool)
    used[F] = True
    remap = np.cumsum(used) - 1
    C = mesh.vertex_colours
    return TriangleMesh(mesh.vertices[used], remap[F], None if C is None else C[used]), used


@dataclass(frozen=True, eq=False)
class FusedMeshes:
    """A fusion's two outputs, in the points' frame.

    observed : the surface the views saw: the fused surface without its unobserved vertices (open; every
        component the points support).
    watertight : the same surface closed (:func:`rangekit.surface.watertight.make_watertight`), its
        ``observed`` flag False on every vertex no input point supports (the closing, the balloon).
    """

    observed: TriangleMesh
    watertight: TriangleMesh

    @property
    def unobserved_area(self) -> float:
        """m^2 of the watertight mesh's triangles with an unobserved corner (what the fusion invented)."""
        m = self.watertight
        invented = ~np.all(m.observed[m.triangles], axis=1)
        a, b, c = (m.vertices[m.triangles[invented, i]] for i in range(3))
        return float(0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum())


def split_observed(surface: TriangleMesh, points: np.ndarray, *, spacing: np.ndarray | None = None,
                   factor: float = OBSERVED_FACTOR, closing: TriangleMesh | None = None) -> FusedMeshes:
    """The observed part of a fused ``surface`` and ``closing`` (default ``surface``) closed and flagged
    (see :class:`FusedMeshes`); ``points`` (N, 3) the fused input points, ``spacing`` and ``factor`` as in
    :func:`observed_vertices`.

    Raises MeshError when no observed triangle is left (the surface is nowhere near the points) or the
    surface cannot be closed.
    """
    from rangekit.surface.watertight import make_watertight

    rule = observed_rule(points, spacing=spacing, factor=factor)
    observed = rule.observed_part(surface)
    return FusedMeshes(observed, rule.flagged(make_watertight(surface if closing is None else closing)))


@dataclass(frozen=True, eq=False)
class ObservedRule:
    """The rule of :func:`observed_vertices` made once for a set of points (:func:`observed_rule`): one k-d
    tree of the points serves their spacing and every mesh's nearest points, so a fusion's two meshes are
    judged as they come (the observed part first, the closed mesh when it is made)."""

    tree: cKDTree         # of the (finite) points
    spacing: np.ndarray   # (N,) metres, per point; NaN where not yet needed (computed as the flags need it)
    median: float         # metres, the median spacing (of every N // MEDIAN_POINTS-th point)
    factor: float
    k: int = SPACING_NEIGHBOURS

    def flags(self, vertices: np.ndarray) -> np.ndarray:
        """(V,) bool: the vertices (V, 3) some point supports."""
        return _within(np.asarray(vertices, dtype=np.float64), self.tree, self.spacing, self.factor, self.median,
                       self.k)

    def observed_part(self, surface: TriangleMesh) -> TriangleMesh:
        """``surface`` without its unobserved vertices (:func:`keep_observed`): every component the points
        support is kept (two ears apart are two components), unlike a closed mesh, its largest component
        closed. MeshError when no triangle is left."""
        return self.observed_near(surface, 1)[0]

    def observed_near(self, surface: TriangleMesh, k: int, workers: int = 1
                      ) -> tuple[TriangleMesh, np.ndarray, np.ndarray]:
        """:meth:`observed_part` and its vertices' ``k`` nearest points from the same k-d tree query: ``(mesh,
        distances (V, k) metres, indices (V, k) into the tree's points)``, nearest first (what
        :func:`rangekit.surface.refine.refine_to_points` projects the vertices with); the query on ``workers``
        threads (scipy's: each vertex's query its own, the same answers), the nearest points' spacing too."""
        from rangekit.errors import MeshError

        V = np.asarray(surface.vertices, dtype=np.float64)
        d, idx = self.tree.query(V, k=k, workers=workers)
        d, idx = d.reshape(len(V), k), idx.reshape(len(V), k)
        flags = _near_enough(d[:, 0], idx[:, 0], self.tree, self.spacing, self.factor, self.median, self.k,
                             workers) if len(V) else np.zeros(0, dtype=bool)
        observed, used = _kept(surface, flags)
        if len(observed.triangles) == 0:
            raise MeshError(f"no triangle of the fused surface ({len(surface.triangles)} triangles) lies within "
                            f"{self.factor:g} point spacings of the {self.tree.n} input points")
        return observed, d[used], idx[used]

    def flagged(self, closed: TriangleMesh) -> TriangleMesh:
        """``closed`` with its per-vertex ``observed`` flag."""
        return closed.with_observed(self.flags(closed.vertices))


def observed_rule(points: np.ndarray, *, spacing: np.ndarray | None = None, factor: float = OBSERVED_FACTOR,
                  k: int = SPACING_NEIGHBOURS) -> ObservedRule:
    """The :class:`ObservedRule` of ``points`` (N, 3), ``spacing`` (N,) and ``factor`` as in
    :func:`observed_vertices`. Without ``spacing`` a point's is computed when a vertex's nearest point is that
    point, and the median from every ``N // MEDIAN_POINTS``-th point's (:data:`MEDIAN_POINTS`)."""
    tree, s = _spaced_tree(points, spacing, factor, k)
    median = np.median(s) if spacing is not None else \
        np.median(_filled(tree, s, np.arange(0, tree.n, max(1, tree.n // MEDIAN_POINTS)), k))
    return ObservedRule(tree, s, float(median), float(factor), k)
