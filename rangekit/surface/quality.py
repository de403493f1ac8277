"""Quality map of a mesh without ground truth: how much the registered views that see a vertex disagree.

For every mesh vertex and every view, the view's surface offset along the vertex normal is the mean
signed distance ``(p - v) . n`` of the view's ``k`` nearest points to the vertex, taken when they all lie
within ``radius``. Where two or more views see a vertex, its disagreement is the standard deviation of
their offsets (ddof 1): noise, a registration error or a calibration error between views shows up as
views that put the surface at different heights. With a single view (or none) it is NaN: nothing to
compare.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from rangekit.errors import InputError

__all__ = ["QualityMap", "vertex_normals", "view_trees", "view_disagreement"]


@dataclass(frozen=True, eq=False)
class QualityMap:
    """Per-vertex disagreement between overlapping views, metres."""

    disagreement: np.ndarray  # (V,) float64 std of the views' offsets along the normal; NaN where < 2 views
    n_views: np.ndarray       # (V,) int64 views that see the vertex
    offsets: np.ndarray       # (n, V) float64 each view's offset along the normal; NaN where it does not see it

    def __repr__(self) -> str:
        d = self.disagreement[np.isfinite(self.disagreement)]
        rms = f", RMS {np.sqrt(np.mean(d ** 2)) * 1e3:.4f} mm" if d.size else ""
        return f"QualityMap({len(self.n_views)} vertices, {d.size} seen by >= 2 views{rms})"


def vertex_normals(vertices: np.ndarray, triangles: np.ndarray, *, sums: np.ndarray | None = None) -> np.ndarray:
    """(V, 3) unit area-weighted vertex normals of a triangle mesh (zero for unused vertices); ``sums``: the
    mesh's :attr:`rangekit.surface.mesh.TriangleMesh.normal_sums` when it has them already."""
    from rangekit.surface.mesh import TriangleMesh

    n = TriangleMesh(vertices, triangles).normal_sums if sums is None else np.asarray(sums, dtype=np.float64)
    return n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)


def view_trees(views: Sequence[np.ndarray]) -> list:
    """Each view's k-d tree (``scipy.spatial.cKDTree`` over its finite points (N_i, 3), float64 metres, in
    ``tree.data``), or None for a view without points: built once for :func:`view_disagreement` and any
    spacing query on the same views. Unbalanced (sliding midpoint): the same neighbours, half the build time."""
    from scipy.spatial import cKDTree

    trees = []
    for P in views:
        P = np.asarray(P, dtype=np.float64).reshape(-1, 3)
        P = P[np.isfinite(P).all(axis=1)]
        trees.append(cKDTree(P, balanced_tree=False) if len(P) else None)
    return trees


def view_disagreement(vertices: np.ndarray, normals: np.ndarray, views: Sequence[np.ndarray] | None = None, *,
                      radius: float, k: int = 4, trees: Sequence | None = None) -> QualityMap:
    """Per-vertex disagreement of registered ``views`` (module doc).

    Parameters
    ----------
    vertices, normals : (V, 3) mesh vertices (metres) and unit normals, in the frame of the views.
    views : n arrays (N_i, 3) of each view's points, registered into the mesh's frame.
    radius : metres; a view sees a vertex when its ``k`` nearest points are all within it (a few times
        the point spacing).
    k : points averaged per view and vertex.
    trees : instead of ``views``, their :func:`view_trees` (built once by a caller that also queries them).

    Returns
    -------
    QualityMap
    """
    Vx = np.asarray(vertices, dtype=np.float64)
    N = np.asarray(normals, dtype=np.float64)
    if Vx.ndim != 2 or Vx.shape[1] != 3 or N.shape != Vx.shape:
        raise InputError(f"view_disagreement: vertices and normals must both be (V, 3), found {Vx.shape} and {N.shape}")
    if not (np.isfinite(radius) and radius > 0):
        raise InputError(f"view_disagreement: radius must be a finite number of metres > 0, found {radius!r}")
    if (views is None) == (trees is None):
        raise InputError("view_disagreement: expected either the views' points or their trees, found "
                         + ("neither" if views is None else "both"))
    trees = view_trees(views) if trees is None else trees
    offsets = np.full((len(trees), len(Vx)), np.nan)
    for i, tree in enumerate(trees):
        if tree is None or tree.n < k:
            continue
        P = tree.data
        dist, idx = tree.query(Vx, k=k, distance_upper_bound=radius)
        dist, idx = dist.reshape(len(Vx), k), idx.reshape(len(Vx), k)
        seen = np.all(np.isfinite(dist), axis=1)
        off = np.einsum("vkj,vj->v", P[idx[seen]] - Vx[seen, None, :], N[seen]) / k
        offsets[i, seen] = off
    n_views = np.sum(np.isfinite(offsets), axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.nanmean(np.where(n_views > 0, offsets, 0.0), axis=0)
        var = np.nansum((offsets - mean) ** 2, axis=0) / (n_views - 1)
    return QualityMap(np.where(n_views >= 2, np.sqrt(var), np.nan), n_views.astype(np.int64), offsets)
