"""A rig checked against a capture that a depth camera saw too (RoomAlive's Kinect v2, docs/real-captures.md).

:func:`capture_fit`: each valid depth pixel back-projected with the depth camera (``rig.cameras[1]``), projected
into the projector, and compared with the projector column and row decoded at the colour camera's pixel
(``rig.cameras[0]``, rounded to the nearest, as RoomAlive looks it up) the same point projects to. A rig that
describes the capture predicts the decoded coordinates to about a pixel; another calibration of the room misses
by hundreds.

:func:`cross_modal`: the Gray-code cloud (each colour camera ray against its decoded column's plane) against the
depth camera's points, and what a decoding error of ``coordinate_error`` projector pixels moves a Gray-code point
by (the geometric limit of a short camera-projector baseline; RoomAlive's projector sits mostly above the camera,
so its rows, not its columns, carry the depth).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.errors import InputError
from rangekit.formats.range_files import DepthMap
from rangekit.rig.rig_file import Rig

__all__ = ["CaptureFit", "CrossModal", "capture_fit", "cross_modal"]

#: RoomAlive's own bound (``CalibrateProjectorGroups``): depth pixels whose variance exceeds 6^2 mm^2 are not used.
MAX_SIGMA_M = 0.006


@dataclass(frozen=True)
class CaptureFit:
    """How well a rig predicts a capture's decoded projector coordinates from the depth camera (projector px)."""

    median_px: float          # median |predicted - decoded| (column and row together)
    p90_px: float
    n_points: int             # depth points that land on a decoded colour pixel


@dataclass(frozen=True)
class CrossModal:
    """The Gray-code cloud against the depth camera's points (metres)."""

    median_m: float           # median distance of a Gray-code point to the nearest depth point
    n_points: int             # Gray-code points compared (those within ``max_distance`` of a depth point)
    n_gray: int               # Gray-code points
    baseline_m: float         # camera-projector baseline
    range_m: float            # median distance of the Gray-code points from the camera
    limit_m: float            # median displacement of a point when its coordinate is off by ``coordinate_error``


def _devices(rig: Rig, where: str):
    if len(rig.cameras) < 2 or rig.projector is None:
        raise InputError(f"{where}: expected a rig with a colour camera, a depth camera (cameras[1]) and a "
                         f"projector, found {len(rig.cameras)} camera(s) and {'a' if rig.projector else 'no'} "
                         f"projector")
    return rig.cameras[0], rig.cameras[1], rig.projector


def capture_fit(rig: Rig, depth: DepthMap, proj_col: np.ndarray, proj_row: np.ndarray, *,
                max_sigma: float = MAX_SIGMA_M) -> CaptureFit:
    """The residual of the projector coordinates ``proj_col``, ``proj_row`` (colour camera pixels, NaN where
    undecoded) predicted from ``depth`` (the depth camera's, pixels of sigma above ``max_sigma`` left out)."""
    colour, depth_cam, projector = _devices(rig, "capture_fit")
    if proj_col.shape != (colour.height, colour.width) or proj_row.shape != proj_col.shape:
        raise InputError(f"capture_fit: decoded maps of shape {proj_col.shape}, {proj_row.shape}; the colour camera "
                         f"is {colour.width}x{colour.height}")
    keep = depth.valid & ~(depth.sigma > max_sigma)
    points = depth.points(depth_cam)[keep]
    uv = np.rint(colour.project(points)).astype(np.int64)
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < colour.width) & (uv[:, 1] >= 0) & (uv[:, 1] < colour.height)
    points, uv = points[inside], uv[inside]
    decoded = np.column_stack([proj_col[uv[:, 1], uv[:, 0]], proj_row[uv[:, 1], uv[:, 0]]])
    seen = np.all(np.isfinite(decoded), axis=1)
    if not np.any(seen):
        raise InputError("capture_fit: no depth point lands on a decoded colour pixel: is this the capture's rig?")
    residual = np.linalg.norm(projector.project(points[seen]) - decoded[seen], axis=1)
    return CaptureFit(float(np.median(residual)), float(np.percentile(residual, 90)), int(seen.sum()))


def cross_modal(rig: Rig, depth: DepthMap, proj_col: np.ndarray, proj_row: np.ndarray | None = None, *,
                coordinate_error: float = 0.1, max_distance: float = 0.5, max_sigma: float = MAX_SIGMA_M) -> CrossModal:
    """The Gray-code cloud against the depth camera's points: the median nearest distance of Gray-code points
    within ``max_distance`` metres of one (farther: seen by one device only), and the geometric limit (module doc).
    The cloud is each colour camera ray against its column's plane (``proj_row`` None; the limit: the column off
    by ``coordinate_error``), or against the projector ray of its column and row (the limit: the row off)."""
    from scipy.spatial import cKDTree

    from rangekit.coded.triangulate import triangulate_ray_plane, triangulate_ray_ray

    colour, depth_cam, projector = _devices(rig, "cross_modal")
    if proj_row is None:
        gray = triangulate_ray_plane(colour, projector, proj_col).xyz
        moved = triangulate_ray_plane(colour, projector, proj_col + coordinate_error).xyz
    else:
        gray = triangulate_ray_ray(colour, projector, proj_col, proj_row).xyz
        moved = triangulate_ray_ray(colour, projector, proj_col, proj_row + coordinate_error).xyz
    ok = np.all(np.isfinite(gray), axis=2) & np.all(np.isfinite(moved), axis=2)
    keep = depth.valid & ~(depth.sigma > max_sigma)
    tof = depth.points(depth_cam)[keep]
    distance, _ = cKDTree(tof).query(gray[ok], distance_upper_bound=max_distance, workers=1)
    near = np.isfinite(distance)
    return CrossModal(float(np.median(distance[near])), int(near.sum()), int(ok.sum()),
                      float(np.linalg.norm(projector.center - colour.center)),
                      float(np.median(np.linalg.norm(gray[ok] - colour.center, axis=1))),
                      float(np.median(np.linalg.norm(moved[ok] - gray[ok], axis=1))))
