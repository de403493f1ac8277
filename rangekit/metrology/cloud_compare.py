"""Two point clouds of one surface compared without a mesh: how far one cloud's points lie from the other's
surface, and how rough a cloud is (issue 35: rangekit's reconstruction of a real capture against its
authors' own point cloud).

- :func:`distances_to_local_planes`: for each query point, its distance to the plane fitted (total least
  squares) to the other cloud's points within ``radius`` of it; NaN where fewer than ``min_points`` are
  near (the other cloud does not cover it there).
- :func:`roughness`: at each query point, the RMS residual of the plane fitted to the cloud's own points
  within ``radius``: noise the surface's own curvature adds little to at a 2 mm radius on a skull-sized
  object.

Both are vectorised over the query points (k-d tree neighbour lists, one batched 3x3 eigen-decomposition).
Units: whatever the clouds are in (metres in rangekit); ``radius`` in the same unit.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["LocalPlanes", "local_planes", "distances_to_local_planes", "roughness"]


class LocalPlanes(NamedTuple):
    """Planes fitted to a cloud's neighbourhoods; NaN rows where fewer than the minimum of points were found."""

    centre: np.ndarray   # (Q, 3) the neighbours' centroid
    normal: np.ndarray   # (Q, 3) unit normal (sign arbitrary)
    rms: np.ndarray      # (Q,) RMS distance of the neighbours to the plane
    count: np.ndarray    # (Q,) neighbours used


def local_planes(cloud: np.ndarray, at: np.ndarray, radius: float, *, min_points: int = 6,
                 max_points: int = 256, chunk: int = 4096) -> LocalPlanes:
    """Total-least-squares planes of the ``cloud`` (N, 3) points within ``radius`` of each of ``at`` (Q, 3), at
    most the ``max_points`` nearest of them (a neighbourhood that holds more is cut to its nearest: keep
    ``radius`` small enough for the cloud's density); ``chunk`` query points at a time bound the memory."""
    cloud = np.asarray(cloud, dtype=np.float64)
    at = np.asarray(at, dtype=np.float64).reshape(-1, 3)
    tree = cKDTree(cloud)
    k = int(max(1, min(max_points, len(cloud))))
    parts = [_planes(cloud, tree, at[i:i + chunk], radius, k, min_points) for i in range(0, len(at), chunk)]
    if not parts:
        return LocalPlanes(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0, dtype=np.int64))
    return LocalPlanes(*(np.concatenate(x) for x in zip(*parts)))


def _planes(cloud, tree, at, radius, k, min_points) -> tuple:
    d, idx = tree.query(at, k=k, distance_upper_bound=radius, workers=1)
    d, idx = d.reshape(len(at), k), idx.reshape(len(at), k)
    valid = np.isfinite(d)
    count = valid.sum(axis=1)
    pts = cloud[np.where(valid, idx, 0)]                                  # (q, k, 3)
    w = valid[..., None].astype(np.float64)
    n = np.maximum(count, 1)[:, None]
    centre = (pts * w).sum(axis=1) / n
    diff = (pts - centre[:, None, :]) * w
    cov = np.einsum("qki,qkj->qij", diff, diff) / n[..., None]
    evals, evecs = np.linalg.eigh(cov)
    normal = evecs[:, :, 0]
    bad = count < min_points
    rms = np.where(bad, np.nan, np.sqrt(np.maximum(evals[:, 0], 0.0)))
    centre[bad], normal[bad] = np.nan, np.nan
    return centre, normal, rms, count


def distances_to_local_planes(query: np.ndarray, cloud: np.ndarray, radius: float, *,
                              min_points: int = 6) -> np.ndarray:
    """(Q,) distance of each ``query`` point to the plane of the ``cloud``'s points within ``radius`` of it; NaN
    where fewer than ``min_points`` of them are there."""
    planes = local_planes(cloud, query, radius, min_points=min_points)
    return np.abs(np.einsum("qi,qi->q", np.asarray(query, float) - planes.centre, planes.normal))


def roughness(cloud: np.ndarray, at: np.ndarray, radius: float, *, min_points: int = 6) -> np.ndarray:
    """(Q,) RMS residual of the plane fitted to the ``cloud``'s own points within ``radius`` of each of ``at``."""
    return local_planes(cloud, at, radius, min_points=min_points).rms
