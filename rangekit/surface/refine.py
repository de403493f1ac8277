"""A fused surface brought back onto the points it was made of: every vertex projected onto the plane its nearest
input points fit (a moving-least-squares projection, Alexa et al. 2003), then the edges whose surface bows away
from their chord halved and their midpoints projected too.

Poisson at octree depth 8 (issue 36) meshes the surface with edges of about 0.7 mm on a 175 mm object: on a
curved part (the upright bunny's ears and face) the flat triangles' middles leave the true surface, and the
vertices follow Poisson's smoothing, not the points. Projecting the vertices puts them on the points; halving
the edges where the surface bows (the sag of a circular arc between the planes' normals at the edge's ends, over
:data:`SPLIT_SAG`) takes the chords back onto it where they left it, and leaves the flat parts as they are: fewer
vertices to project, write and measure than halving every edge (issue 51: the refinement's CPU).

- :func:`mesh_edges`: a mesh's edges, each once, and each triangle's three.
- :func:`subdivide_edges`: the chosen edges halved, every triangle split into 1-4 so the mesh stays one manifold
  (a red-green refinement of one level).
- :func:`subdivide_midpoint`: every edge halved (every triangle into four).
- :func:`project_to_points`: each vertex onto the weighted plane of its ``k`` nearest oriented input points.
- :func:`refine_to_points`: the observed mesh's last step (:func:`rangekit.app.process.fuse.save_observed`).

Units are metres; the mesh and the points share one frame. Deterministic (scipy's k-d tree, no threads).
"""

from __future__ import annotations

import numpy as np

from rangekit.errors import InputError
from rangekit.surface.mesh import TriangleMesh

__all__ = ["REFINE_NEIGHBOURS", "SPLIT_SAG", "mesh_edges", "subdivide_edges", "subdivide_midpoint",
           "project_to_points", "edge_sag", "refine_to_points"]

#: Input points whose weighted plane a vertex is projected onto. On the 12-view upright bunny (616k points, about
#: 0.2 mm apart): 6 gave 0.0124 mm RMS, 10 gave 0.0134, 20 gave 0.0163 (a wider plane cuts the curved parts).
REFINE_NEIGHBOURS = 6
#: An edge is halved where the surface between its ends bows more than this from the chord (metres). On the
#: 12-view upright bunny (Poisson depth 8, 158k observed vertices): every edge halved 0.0125 / 0.0235 mm RMS / 95th
#: percentile at 3.99x the vertices; 8 um 0.0129 / 0.0242 at 1.58x; 16 um 0.0141 / 0.0271 at 1.16x; none 0.0169 /
#: 0.0325. On the default (lumpy) object: all 0.0068 / 0.0135 at 3.99x, 8 um 0.0069 / 0.0137 at 1.12x, none 0.0072.
SPLIT_SAG = 8e-6
#: Points projected at once: the (chunk, k, 3) neighbourhoods stay a few tens of MB.
_CHUNK = 65_536


def mesh_edges(triangles: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """``(edges (E, 2) int64, lower index first, sorted; edge_of (3, F))``: each edge of the (F, 3) ``triangles``
    once, and triangle ``i``'s edges (its corners 0-1, 1-2, 2-0) as rows ``edge_of[:, i]`` of ``edges``."""
    F = np.asarray(triangles, dtype=np.int64)
    a, b = np.concatenate([F[:, 0], F[:, 1], F[:, 2]]), np.concatenate([F[:, 1], F[:, 2], F[:, 0]])
    key = np.minimum(a, b) * n_vertices + np.maximum(a, b)      # one int64 a edge: a 1-D sort, not rows'
    unique, edge_of = np.unique(key, return_inverse=True)
    return np.column_stack([unique // n_vertices, unique % n_vertices]), edge_of.reshape(3, len(F))


def subdivide_edges(mesh: TriangleMesh, split: np.ndarray, edges: np.ndarray | None = None,
                    edge_of: np.ndarray | None = None) -> TriangleMesh:
    """``mesh`` with its edges where ``split`` (E,) bool (of :func:`mesh_edges`' ``edges``) halved: their midpoints
    appended after the vertices in edge order (colours the ends' mean), and each triangle with 1, 2 or 3 halved
    edges split into 2, 3 or 4 of the same winding (with two, the quad left across the shorter diagonal). An edge's
    midpoint is shared by the triangles on either side: a closed or open manifold stays one."""
    V, F = mesh.vertices, np.asarray(mesh.triangles, dtype=np.int64)
    if edges is None or edge_of is None:
        edges, edge_of = mesh_edges(F, len(V))
    split = np.asarray(split, dtype=bool)
    if split.shape != (len(edges),):
        raise InputError(f"subdivide_edges: split must be ({len(edges)},) bool, one per edge, found {split.shape}")
    cut = edges[split]
    mid = np.full(len(edges), -1, dtype=np.int64)
    mid[split] = len(V) + np.arange(len(cut))
    vertices = np.concatenate([V, 0.5 * (V[cut[:, 0]] + V[cut[:, 1]])])
    colours = None
    if mesh.vertex_colours is not None:
        C = mesh.vertex_colours
        colours = np.concatenate([C, (0.5 * (C[cut[:, 0]] + C[cut[:, 1]])).astype(C.dtype)])
    m = mid[edge_of].T                                     # (F, 3): the midpoint of edge j (corner j to j+1), or -1
    marked = m >= 0
    count = marked.sum(axis=1)
    # Turn each triangle's corners so its pattern is one of three: one halved edge at 0-1; two at 0-1 and 1-2.
    first = np.argmax(marked, axis=1)                      # one halved edge: that edge
    unmarked = np.argmin(marked, axis=1)                   # two: the edge left whole goes to 2-0
    turn = np.where(count == 2, (unmarked + 1) % 3, np.where(count == 1, first, 0))
    cols = (turn[:, None] + np.arange(3)) % 3
    Ft = np.take_along_axis(F, cols, axis=1)
    mt = np.take_along_axis(m, cols, axis=1)
    a, b, c = Ft[:, 0], Ft[:, 1], Ft[:, 2]
    ab, bc, ca = mt[:, 0], mt[:, 1], mt[:, 2]
    parts = [F[count == 0]]
    one = count == 1
    parts += [np.stack([a[one], ab[one], c[one]], 1), np.stack([ab[one], b[one], c[one]], 1)]
    two = count == 2
    a2, b2, c2, ab2, bc2 = a[two], b[two], c[two], ab[two], bc[two]
    # The quad a, ab, bc, c: across a-bc or across ab-c, the shorter.
    short = (np.linalg.norm(vertices[a2] - vertices[bc2], axis=1)
             <= np.linalg.norm(vertices[ab2] - vertices[c2], axis=1))
    parts += [np.stack([ab2, b2, bc2], 1),
              np.where(short[:, None], np.stack([a2, ab2, bc2], 1), np.stack([a2, ab2, c2], 1)),
              np.where(short[:, None], np.stack([a2, bc2, c2], 1), np.stack([ab2, bc2, c2], 1))]
    three = count == 3
    a3, b3, c3, ab3, bc3, ca3 = a[three], b[three], c[three], ab[three], bc[three], ca[three]
    parts += [np.stack([a3, ab3, ca3], 1), np.stack([ab3, b3, bc3], 1), np.stack([ca3, bc3, c3], 1),
              np.stack([ab3, bc3, ca3], 1)]
    return TriangleMesh(vertices, np.concatenate(parts), colours)


def subdivide_midpoint(mesh: TriangleMesh) -> TriangleMesh:
    """``mesh`` with every triangle split into four at its edges' midpoints (V + E vertices, 4 F triangles, the
    same winding): :func:`subdivide_edges` of every edge."""
    if len(mesh.triangles) == 0:
        return mesh
    edges, edge_of = mesh_edges(mesh.triangles, len(mesh.vertices))
    return subdivide_edges(mesh, np.ones(len(edges), dtype=bool), edges, edge_of)


def _checked(vertices, points, normals, k) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    P = np.asarray(points, dtype=np.float64)
    Nm = np.asarray(normals, dtype=np.float64)
    V = np.asarray(vertices, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3 or Nm.shape != P.shape or len(P) < 1:
        raise InputError(f"project_to_points: points and normals must be (N, 3), N >= 1, found {P.shape} and "
                         f"{Nm.shape}")
    if V.ndim != 2 or V.shape[1] != 3:
        raise InputError(f"project_to_points: vertices must be (V, 3), found {V.shape}")
    if not (isinstance(k, (int, np.integer)) and k >= 1):
        raise InputError(f"project_to_points: k must be an integer >= 1, found {k!r}")
    return V, P, Nm


def _project(V: np.ndarray, P: np.ndarray, Nm: np.ndarray, k: int, tree,
             near: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """:func:`project_to_points` on checked arrays, and the planes' unit normals (V, 3) (zero where the
    neighbours' normals cancel). ``near``: the vertices' ``k`` nearest points as the tree's query gives them
    (distances, indices; (V, k) each), when already queried."""
    if tree is None and near is None:
        from scipy.spatial import cKDTree

        tree = cKDTree(P)
    k = int(min(k, len(P)))
    out, normal = V.copy(), np.zeros_like(V)
    for start in range(0, len(V), _CHUNK):
        Q = V[start:start + _CHUNK]
        if near is None:
            d, idx = tree.query(Q, k=k)
        else:
            d, idx = near[0][start:start + _CHUNK], near[1][start:start + _CHUNK]
        d, idx = d.reshape(len(Q), k), idx.reshape(len(Q), k)
        sigma = np.maximum(0.5 * d[:, -1:], 1e-12)
        w = np.exp(-(d / sigma) ** 2)
        w /= w.sum(axis=1, keepdims=True)
        centre = np.einsum("vk,vkd->vd", w, P[idx])
        n = np.einsum("vk,vkd->vd", w, Nm[idx])
        length = np.linalg.norm(n, axis=1, keepdims=True)
        n = np.divide(n, length, out=np.zeros_like(n), where=length > 0)   # opposed normals: the vertex stays
        out[start:start + _CHUNK] = Q - np.einsum("vd,vd->v", Q - centre, n)[:, None] * n
        normal[start:start + _CHUNK] = n
    return out, normal


def project_to_points(vertices: np.ndarray, points: np.ndarray, normals: np.ndarray, *, k: int = REFINE_NEIGHBOURS,
                      tree=None, near: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """(V, 3): each of ``vertices`` (V, 3) moved along the weighted mean normal of its ``k`` nearest ``points``
    (N, 3) onto the plane through their weighted mean. ``normals`` (N, 3) unit, the points' (their sign does not
    matter beyond the neighbourhood agreeing). Weights fall as a Gaussian of the distance with sigma half the
    ``k``-th neighbour's distance. ``tree``: a ``scipy.spatial.cKDTree`` of ``points``, if one is at hand;
    ``near``: the vertices' ``k`` nearest points (distances, indices; (V, k) each), when already queried."""
    V, P, Nm = _checked(vertices, points, normals, k)
    _check_near(near, len(V), min(k, len(P)))
    return _project(V, P, Nm, k, tree, near)[0]


def _check_near(near, n_vertices: int, k: int) -> None:
    if near is not None and (np.shape(near[0]) != (n_vertices, k) or np.shape(near[1]) != np.shape(near[0])):
        raise InputError(f"refine_to_points: near must be two ({n_vertices}, {k}) arrays, found "
                         f"{np.shape(near[0])} and {np.shape(near[1])}")


def edge_sag(vertices: np.ndarray, normals: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """(E,) metres: how far the surface bows from each chord of ``edges`` (E, 2) between ``vertices`` (V, 3) whose
    surface normals are ``normals`` (V, 3, unit): an arc turning from one end's normal to the other's leaves its
    chord by ``|e . (n1 - n0)| / 8`` at the middle (``L^2 / 8R`` for a circle of radius R; ``e`` the chord)."""
    e = vertices[edges[:, 1]] - vertices[edges[:, 0]]
    return np.abs(np.einsum("ed,ed->e", e, normals[edges[:, 1]] - normals[edges[:, 0]])) / 8


def refine_to_points(mesh: TriangleMesh, points: np.ndarray, normals: np.ndarray, *, k: int = REFINE_NEIGHBOURS,
                     tree=None, sag: float = SPLIT_SAG, near: tuple[np.ndarray, np.ndarray] | None = None
                     ) -> TriangleMesh:
    """``mesh`` on the oriented ``points``' surface: its vertices projected (:func:`project_to_points`), its edges
    whose surface bows more than ``sag`` metres from the chord (:func:`edge_sag`, from the planes' normals at the
    ends) halved (:func:`subdivide_edges`) and their midpoints projected too. ``sag`` 0: every edge halved (every
    triangle into four). An empty mesh is returned as it is. ``near``: the vertices' ``k`` nearest points,
    ``(distances, indices)`` (V, k) each as ``tree.query(mesh.vertices, k)`` gives them, when already queried
    (:meth:`rangekit.surface.observed.ObservedRule.observed_near`: the observed cut's query, not made twice)."""
    if len(mesh.triangles) == 0:
        return mesh
    if not sag >= 0:
        raise InputError(f"refine_to_points: sag must be >= 0 metres, found {sag!r}")
    V, P, Nm = _checked(mesh.vertices, points, normals, k)
    _check_near(near, len(V), min(k, len(P)))
    placed, n = _project(V, P, Nm, k, tree, near)
    edges, edge_of = mesh_edges(mesh.triangles, len(V))
    split = edge_sag(placed, n, edges) > sag if sag > 0 else np.ones(len(edges), dtype=bool)
    fine = subdivide_edges(TriangleMesh(placed, mesh.triangles, mesh.vertex_colours), split, edges, edge_of)
    new = fine.vertices.copy()
    new[len(V):] = _project(fine.vertices[len(V):], P, Nm, k, tree)[0]
    return TriangleMesh(new, fine.triangles, fine.vertex_colours)
