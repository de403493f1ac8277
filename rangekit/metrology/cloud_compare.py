"""Two point clouds of one surface compared without a mesh: how far one cloud's points lie from the other's
surface, and how rough a cloud is (issue 35: rangekit's reconstruction of a real capture against its
authors' own point cloud).

- :func:`distances_to_local_planes`: for each query point, its distance to the plane fitted (total least
  squares) to the other cloud's points within ``radius`` of it; NaN where fewer than ``min_points`` are
  near (the other cloud does not cover it there).
- :func:`roughness`: at each query point, the RMS residual of the plane fitted to the cloud's own points
  within ``radius``: noise the surface's own curvature adds little to at a 2 mm radius on a skull-sized
  object. Every point within the radius counts (no cap at the nearest ones), so two clouds measured at the
  same points and radius are measured over the same patch.

Both are vectorised over the query points (k-d tree neighbour lists, one batched 3x3 eigen-decomposition).
Units: whatever the clouds are in (metres in rangekit); ``radius`` in the same unit.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["CHUNK_SLOTS", "LocalPlanes", "local_planes", "distances_to_local_planes", "distances_to_nearest_planes",
           "roughness"]


class LocalPlanes(NamedTuple):
    """Planes fitted to a cloud's neighbourhoods; NaN rows where fewer than the minimum of points were found."""

    centre: np.ndarray   # (Q, 3) the neighbours' centroid
    normal: np.ndarray   # (Q, 3) unit normal (sign arbitrary)
    rms: np.ndarray      # (Q,) RMS distance of the neighbours to the plane
    count: np.ndarray    # (Q,) neighbours used


#: Neighbour slots (query points x neighbours) a chunk of :func:`local_planes` holds at most: 4M, about 100 MB
#: of coordinates; a cloud denser than that in one neighbourhood is taken a few query points at a time.
CHUNK_SLOTS = 1 << 22


def local_planes(cloud: np.ndarray, at: np.ndarray, radius: float, *, min_points: int = 6) -> LocalPlanes:
    """Total-least-squares planes of the ``cloud`` (N, 3) points within ``radius`` of each of ``at`` (Q, 3).

    Every point within the radius is used, however many: two clouds of one surface compared at the same
    ``at`` and ``radius`` are measured over the same patch whatever their densities (a cap at the nearest
    points would shrink the denser cloud's patch and flatter its roughness). The query points are taken in
    chunks of at most :data:`CHUNK_SLOTS` neighbour slots."""
    cloud = np.asarray(cloud, dtype=np.float64)
    at = np.asarray(at, dtype=np.float64).reshape(-1, 3)
    if len(at) == 0 or len(cloud) == 0:
        nan = np.full((len(at), 3), np.nan)
        return LocalPlanes(nan, nan.copy(), np.full(len(at), np.nan), np.zeros(len(at), dtype=np.int64))
    tree = cKDTree(cloud)
    counts = np.asarray(tree.query_ball_point(at, radius, return_length=True, workers=1), dtype=np.int64)
    order = np.argsort(counts, kind="stable")          # chunks of alike counts: few empty slots
    parts, start = [], 0
    while start < len(at):
        k = max(1, int(counts[order[min(len(at), start + 64) - 1]]))
        stop = start + max(1, CHUNK_SLOTS // k)
        k = max(1, int(counts[order[min(len(at), stop) - 1]]))
        parts.append(_planes(cloud, tree, at[order[start:stop]], radius, k, min_points))
        start = stop
    planes = [np.concatenate(x) for x in zip(*parts)]
    back = np.empty_like(order)
    back[order] = np.arange(len(order))
    return LocalPlanes(*(x[back] for x in planes))


def _planes(cloud, tree, at, radius, k, min_points) -> tuple:
    d, idx = tree.query(at, k=k, distance_upper_bound=radius * (1 + 1e-12), workers=1)
    d, idx = d.reshape(len(at), k), idx.reshape(len(at), k)
    valid = np.isfinite(d) & (d <= radius)
    count = valid.sum(axis=1)
    pts = cloud[np.where(valid, idx, 0)] - at[:, None, :]               # (q, k, 3), about the query point
    w = valid[..., None].astype(np.float64)
    n = np.maximum(count, 1)[:, None]
    centre = (pts * w).sum(axis=1) / n
    diff = (pts - centre[:, None, :]) * w
    cov = np.einsum("qki,qkj->qij", diff, diff) / n[..., None]
    evals, evecs = np.linalg.eigh(cov)
    normal = evecs[:, :, 0]
    bad = count < min_points
    rms = np.where(bad, np.nan, np.sqrt(np.maximum(evals[:, 0], 0.0)))
    centre = centre + at
    centre[bad], normal[bad] = np.nan, np.nan
    return centre, normal, rms, count


def distances_to_local_planes(query: np.ndarray, cloud: np.ndarray, radius: float, *,
                              min_points: int = 6) -> np.ndarray:
    """(Q,) distance of each ``query`` point to the plane of the ``cloud``'s points within ``radius`` of it; NaN
    where fewer than ``min_points`` of them are there."""
    planes = local_planes(cloud, query, radius, min_points=min_points)
    return np.abs(np.einsum("qi,qi->q", np.asarray(query, float) - planes.centre, planes.normal))


def distances_to_nearest_planes(query: np.ndarray, cloud: np.ndarray, *, k: int = 8, max_radius: float,
                                signed: bool = False) -> np.ndarray:
    """(Q,) distance of each ``query`` point to the plane of its ``k`` nearest ``cloud`` points; NaN where the
    k-th of them is farther than ``max_radius`` (the cloud does not cover the point there).

    The measure of a reference cloud's points against clouds of different densities that favours none of
    them for its density: each cloud gives each reference point the same number of points. ``signed``: the
    distance along the plane's normal turned away from the origin (a camera-frame cloud: positive where the
    query point lies beyond the cloud's surface, seen from the camera)."""
    query = np.asarray(query, dtype=np.float64).reshape(-1, 3)
    cloud = np.asarray(cloud, dtype=np.float64)
    d, idx = cKDTree(cloud).query(query, k=k, workers=1)
    d, idx = d.reshape(len(query), k), idx.reshape(len(query), k)
    pts = cloud[np.minimum(idx, len(cloud) - 1)]
    centre = pts.mean(axis=1)
    diff = pts - centre[:, None, :]
    _, evecs = np.linalg.eigh(np.einsum("qki,qkj->qij", diff, diff))
    normal = evecs[:, :, 0]
    normal *= np.where(np.einsum("qi,qi->q", normal, centre) < 0, -1.0, 1.0)[:, None]
    out = np.einsum("qi,qi->q", query - centre, normal)
    out = out if signed else np.abs(out)
    return np.where(d[:, -1] <= max_radius, out, np.nan)


def roughness(cloud: np.ndarray, at: np.ndarray, radius: float, *, min_points: int = 6) -> np.ndarray:
    """(Q,) RMS residual of the plane fitted to the ``cloud``'s own points within ``radius`` of each of ``at``."""
    return local_planes(cloud, at, radius, min_points=min_points).rms
