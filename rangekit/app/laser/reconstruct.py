"""From a laser capture to a point cloud: each laser's line peaks (laser on minus laser off), each peak's
ray triangulated against that laser's plane (with the lens distortion), the lasers merged.

The points are in the rig's world frame at the capture's turntable position (as the coded-light
``reconstruct`` writes them); a scan rotates each profile into one frame
(:func:`rangekit.laser.to_turntable_frame`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.errors import DecodeError
from rangekit.formats.laser_capture import LaserCapture
from rangekit.laser import LinePeaks, detect_peaks, require_peaks, triangulate_peaks
from rangekit.laser.profile_filter import JUMP_FOOTPRINTS, continuous_runs, pixel_footprint
from rangekit.surface.cloud import PointCloud

__all__ = ["LaserReconstruction", "reconstruct_laser_capture"]


@dataclass(frozen=True, eq=False)
class LaserReconstruction:
    """``cloud`` the merged points (colour from the laser-off image); per laser its ``peaks`` and how many
    points triangulated (``n_points``) and how many rays were refused (``n_refused``: grazing, behind, or off a continuous run of the line)."""

    cloud: PointCloud
    peaks: tuple[LinePeaks, ...]
    n_points: tuple[int, ...]
    n_refused: tuple[int, ...]
    laser_index: np.ndarray   # (N,) int: which laser lit each point of ``cloud``

    def summary(self) -> str:
        per = ", ".join(f"laser {k}: {n:,} points ({r} rays refused)"
                        for k, (n, r) in enumerate(zip(self.n_points, self.n_refused)))
        return f"{len(self.cloud):,} points; {per}"


def reconstruct_laser_capture(capture: LaserCapture, *, method: str = "gaussian",
                              full_scale: float | None = None, require: bool = True,
                              min_run: int = 5, regions=None) -> LaserReconstruction:
    """Peaks, triangulation and merge of every laser of ``capture``; a laser whose line is not visible is a
    :class:`DecodeError` naming its frame (never a silently empty cloud). ``full_scale``: the camera's
    largest value (saturation and colour scale), default the capture's (its bits), else the dtype's.
    ``require=False`` (one step of a scan, where a line may miss everything at some angles): such a laser
    gives no points, and the scan counts it (``n_points`` 0). ``min_run``: row-method points are kept in
    continuous runs of at least this many rows (:func:`rangekit.laser.profile_filter.continuous_runs`; 1: all).
    ``regions``: per laser an (H, W) bool mask of where its line may be, or None
    (:func:`rangekit.laser.triangulate.plane_region`: above the turntable top)."""
    rig, camera = capture.rig, capture.rig.camera
    colour = capture.off.ndim == 3
    saturation = full_scale or capture.full_scale or float(np.iinfo(capture.off.dtype).max)
    points, colours, which, all_peaks, counts, refused = [], [], [], [], [], []
    for k, (laser, frame) in enumerate(zip(rig.lasers, capture.frames)):
        name = str(capture.folder / capture.names[k])
        peaks = detect_peaks(frame, capture.off, method=method, channel=laser.channel if colour else None,
                             saturation=saturation, mask=None if regions is None else regions[k])
        if require:
            peaks = require_peaks(peaks, name)
        tri = triangulate_peaks(peaks.points, camera, laser)
        ok = tri.valid
        if peaks.rows is not None and min_run > 1:   # row methods: drop the blurred line ends' ghost peaks
            ok &= continuous_runs(peaks.rows, tri.xyz, min_run=min_run,
                                  max_jump=JUMP_FOOTPRINTS * pixel_footprint(tri.xyz, camera))
        if require and not ok.any():
            raise DecodeError(f"{name}: {len(peaks)} line peaks, but none triangulates against laser {laser.name!r} "
                              f"({tri.n_grazing} rays graze its plane, {tri.n_behind} meet it behind the camera)")
        uv = np.rint(peaks.points[ok]).astype(np.int64)
        off = capture.off[uv[:, 1], uv[:, 0]].astype(np.float32) / saturation
        colours.append(off if colour else np.repeat(off[:, None], 3, axis=1))
        points.append(tri.xyz[ok])
        which.append(np.full(int(ok.sum()), k))
        all_peaks.append(peaks)
        counts.append(int(ok.sum()))
        refused.append(int((~ok).sum()))
    if not sum(counts):
        cloud = PointCloud(np.zeros((0, 3)), colours=np.zeros((0, 3), np.float32))
    else:
        cloud = PointCloud(np.concatenate(points), colours=np.clip(np.concatenate(colours), 0, 1))
    return LaserReconstruction(cloud, tuple(all_peaks), tuple(counts), tuple(refused), np.concatenate(which))
