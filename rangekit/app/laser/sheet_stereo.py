"""From a two-camera laser capture to a point cloud (laser-sheet stereo, :mod:`rangekit.laser.sheet_stereo`): each
laser's line peaks in both cameras (laser on minus laser off), each left peak met with the right line on its
epipolar line and triangulated by the pair; by default the left peaks the right camera does not see are then met
with the sheet fitted to that frame's pair points (``fill``); the lasers merged. No laser plane is given: the rig
file's ``lasers`` may be absent.

The points are in the rig's world frame at the capture's turntable position, as
:func:`rangekit.app.laser.reconstruct.reconstruct_laser_capture` writes a one-camera capture's; a scan turns each
profile back by its angle (:func:`rangekit.laser.to_turntable_frame`). Points off a continuous run of the left line
are dropped as there (:mod:`rangekit.laser.profile_filter`): a matched peak of a blurred line end is isolated.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from rangekit.errors import DecodeError
from rangekit.formats.laser_capture import LaserStereoCapture
from rangekit.laser import LinePeaks, detect_peaks, require_peaks
from rangekit.laser.profile_filter import JUMP_FOOTPRINTS, continuous_runs, pixel_footprint
from rangekit.laser.sheet_stereo import SheetStereoPoints, fill_from_sheet, sheet_stereo
from rangekit.progress import call_progress
from rangekit.stereo.rectify import Rectification, rectify
from rangekit.surface.cloud import PointCloud

__all__ = ["LaserStereoReconstruction", "reconstruct_laser_stereo_capture", "report_laser_stereo_truth"]


@dataclass(frozen=True, eq=False)
class LaserStereoReconstruction:
    """``cloud`` the merged points (colour from the left laser-off image); per laser the ``peaks`` (left,
    right), what the matching gave (``matched``: one row per left peak), ``xyz`` (N, 3) the point of each left
    peak (the pair's, or filled in from the sheet; NaN: none), ``filled`` (N,) bool the points filled in,
    ``kept`` (N,) bool the points of ``cloud`` (after the continuity filter), in order, and their number
    (``n_points``); ``laser_index`` (M,) which laser lit each point of ``cloud``."""

    cloud: PointCloud
    peaks: tuple[tuple[LinePeaks, LinePeaks], ...]
    matched: tuple[SheetStereoPoints, ...]
    xyz: tuple[np.ndarray, ...]
    filled: tuple[np.ndarray, ...]
    kept: tuple[np.ndarray, ...]
    n_points: tuple[int, ...]
    laser_index: np.ndarray
    exchanged: bool = False        # left/ held the right camera's frames (the pair fits only so): taken as such

    def pairing_line(self) -> str:
        """One line when the folders were exchanged (empty otherwise)."""
        return ("cameras EXCHANGED: left/ holds the rig's right camera's frames and right/ its left's (the pair "
                "matches the laser line only so); triangulated as such") if self.exchanged else ""

    def summary(self) -> str:
        per = ", ".join(f"laser {k}: {n:,} points ({int((f & ok).sum()):,} filled in from the sheet) from "
                        f"{len(p[0]):,} left and {len(p[1]):,} right peaks ({m.n_unmatched} unmatched, "
                        f"{m.n_ambiguous} ambiguous, {m.n_off_sheet} off the sheet)"
                        for k, (n, p, m, f, ok) in enumerate(zip(self.n_points, self.peaks, self.matched, self.filled,
                                                                   self.kept)))
        return f"{len(self.cloud):,} points; {per}"


def reconstruct_laser_stereo_capture(capture: LaserStereoCapture, *, method: str = "gaussian",
                                     full_scale: float | None = None, require: bool = True, min_run: int = 5,
                                     fill: bool = True, rect: Rectification | None = None,
                                     **match_options) -> LaserStereoReconstruction:
    """Peaks in both cameras, matching, triangulation and merge of every laser of ``capture`` (module doc).

    ``method``: a row method of :func:`rangekit.laser.detect_peaks` (gaussian, com, argmax). ``full_scale``: the
    cameras' largest value, default the capture's (its bits), else the dtype's. ``require=False`` (one step of a
    scan, where a line may miss everything): a laser without a line or a match gives no points; with True that is
    a :class:`DecodeError` naming its frame. ``min_run``: points kept in continuous runs of at least this many
    left rows (1: all). ``fill``: the left peaks the pair did not triangulate met with the frame's fitted sheet
    (:func:`rangekit.laser.sheet_stereo.fill_from_sheet`); False: the pair's points only. ``rect``: the pair's
    rectification, made once for many captures of one rig.
    ``match_options``: :func:`rangekit.laser.sheet_stereo.match_sheet`'s (``max_step``, ``min_depth``, ``max_depth``).
    """
    left_cam, right_cam = capture.rig.cameras[:2]
    rect = rect if rect is not None else rectify(left_cam, right_cam)
    off_l = capture.off[0]
    colour = off_l.ndim == 3
    saturation = full_scale or capture.full_scale or float(np.iinfo(off_l.dtype).max)
    points, colours, which, all_peaks, matched, counts, kept, xyzs, fills = [], [], [], [], [], [], [], [], []

    def peaks_of(side: int, k: int):
        return detect_peaks(capture.frames[side][k], capture.off[side], method=method,
                            channel=capture.channels[k] if colour else None, saturation=saturation)

    sides = _sides(capture, peaks_of, left_cam, right_cam, rect, match_options)
    off_l = capture.off[sides[0]]
    for k in range(capture.n_lasers):
        pair = []
        for side in sides:
            peaks = peaks_of(side, k)
            pair.append(require_peaks(peaks, str(capture.path(side, k))) if require else peaks)
        res = sheet_stereo(pair[0], pair[1], left_cam, right_cam, rect=rect, **match_options)
        xyz, filled = res.xyz, np.zeros(len(res.xyz), dtype=bool)
        if fill:
            more = fill_from_sheet(res, pair[0].points, left_cam)
            filled = np.isfinite(more[:, 0])
            xyz = np.where(filled[:, None], more, xyz)
        ok = np.isfinite(xyz[:, 0])
        if min_run > 1:
            ok &= continuous_runs(pair[0].rows, xyz, min_run=min_run,
                                  max_jump=JUMP_FOOTPRINTS * pixel_footprint(xyz, left_cam))
        if require and not ok.any():
            raise DecodeError(f"{capture.path(sides[0], k)} and {capture.path(sides[1], k)}: {len(pair[0])} left and "
                              f"{len(pair[1])} "
                              f"right line peaks, but no left peak meets the right line on its epipolar line "
                              f"({res.n_unmatched} unmatched, {res.n_ambiguous} ambiguous): do both cameras see laser "
                              f"{k}'s line, and is the rig's cameras[1] the right camera of this pair?")
        uv = np.rint(pair[0].points[ok]).astype(np.int64)
        off = off_l[uv[:, 1], uv[:, 0]].astype(np.float32) / saturation
        colours.append(off if colour else np.repeat(off[:, None], 3, axis=1))
        points.append(xyz[ok])
        xyzs.append(xyz)
        fills.append(filled)
        which.append(np.full(int(ok.sum()), k))
        all_peaks.append(tuple(pair))
        matched.append(res)
        counts.append(int(ok.sum()))
        kept.append(ok)
    if not sum(counts):
        cloud = PointCloud(np.zeros((0, 3)), colours=np.zeros((0, 3), np.float32))
    else:
        cloud = PointCloud(np.concatenate(points), colours=np.clip(np.concatenate(colours), 0, 1))
    return LaserStereoReconstruction(cloud, tuple(all_peaks), tuple(matched), tuple(xyzs), tuple(fills), tuple(kept),
                                     tuple(counts), np.concatenate(which), sides == (1, 0))


#: The folders are taken exchanged when, so, the matched points lie on their light sheets this many times closer
#: (the sheet's robust sigma; a swapped pair's points are the wrong rays' crossings, millimetres off any plane: on
#: the simulator 2.50 mm as named against 0.039 mm exchanged).
EXCHANGE_RATIO = 4.0


def _sides(capture: LaserStereoCapture, peaks_of, left_cam, right_cam, rect, match_options) -> tuple[int, int]:
    """(0, 1): left/ is the rig's left camera, as named; (1, 0) when the lasers' matched points lie
    :data:`EXCHANGE_RATIO` times closer to their sheets the other way round (issue 48: exchanged folders gave
    17.9 mm RMS). Lasers whose points fix no sheet either way do not vote; with none, as named."""
    ratios = []
    for k in range(capture.n_lasers):
        peaks = [peaks_of(0, k), peaks_of(1, k)]
        if min(len(peaks[0]), len(peaks[1])) == 0:
            continue
        sheets = [sheet_stereo(peaks[a], peaks[b], left_cam, right_cam, rect=rect, **match_options).sheet
                  for a, b in ((0, 1), (1, 0))]
        if all(sh is not None and sh.plane is not None and sh.sigma > 0 for sh in sheets):
            ratios.append(sheets[0].sigma / sheets[1].sigma)
    return (1, 0) if ratios and np.median(ratios) > EXCHANGE_RATIO else (0, 1)


def report_laser_stereo_truth(capture: LaserStereoCapture, rec: LaserStereoReconstruction,
                              progress: Callable | None = None) -> dict | None:
    """Say how ``rec`` compares with the simulator's ``ground_truth.npz`` in the capture's folder (when there is
    one with the left camera's lit curves): each point against the true lit curve where it crosses the point's
    left row (:func:`rangekit.sim.laser.truth.curve_at_rows`), the pair's points and those filled in apart, and
    the share of the rows where the left camera sees the true curve (and of those where both cameras see it) that
    got a point. Returns the figures (metres), or None without truth."""
    from rangekit.formats.range_files import load_ground_truth
    from rangekit.sim.laser.truth import curve_at_rows

    truth = load_ground_truth(capture.folder)
    if truth is None or any(f"left_laser{k}_curve_uv" not in truth for k in range(capture.n_lasers)):
        return None
    pair_e, fill_e, rows_got, n_left, n_both = [], [], [0, 0], 0, 0
    for k, (peaks, ok) in enumerate(zip(rec.peaks, rec.kept)):
        uv, xyz = truth[f"left_laser{k}_curve_uv"], truth[f"left_laser{k}_curve_xyz"]
        true = curve_at_rows(peaks[0].points[ok], uv, xyz)
        e = np.linalg.norm(rec.xyz[k][ok] - true, axis=1)
        filled = rec.filled[k][ok]
        pair_e.append(e[~filled & np.isfinite(e)])
        fill_e.append(e[filled & np.isfinite(e)])
        rows = peaks[0].rows[ok]
        for i, mask in enumerate((None, truth.get(f"left_laser{k}_both"))):
            seen = np.unique(np.rint(uv[slice(None) if mask is None else mask, 1]).astype(np.int64))
            rows_got[i] += int(np.isin(rows, seen).sum())
            n_left, n_both = (n_left + len(seen), n_both) if i == 0 else (n_left, n_both + len(seen))
    e_pair, e_fill = np.concatenate(pair_e), np.concatenate(fill_e)
    e = np.concatenate([e_pair, e_fill])
    if e.size == 0:
        return None
    rms = lambda a: float(np.sqrt(np.mean(a ** 2))) if a.size else float("nan")   # noqa: E731
    figures = {"n_compared": int(e.size), "rms": rms(e), "median": float(np.median(e)),
               "p99": float(np.percentile(e, 99)), "pair_rms": rms(e_pair), "n_filled": int(e_fill.size),
               "filled_rms": rms(e_fill), "rows_left": rows_got[0] / max(n_left, 1),
               "rows_both": rows_got[1] / max(n_both, 1)}
    call_progress(progress, f"against ground_truth.npz ({e.size:,} points): distance to the true lit curve at the "
                            f"point's left row RMS {figures['rms'] * 1e3:.3f} mm, median {figures['median'] * 1e3:.3f} "
                            f"mm, 99th percentile {figures['p99'] * 1e3:.3f} mm"
                            + (f" (the pair's points {figures['pair_rms'] * 1e3:.3f} mm, the {e_fill.size:,} filled in "
                               f"from the sheet {figures['filled_rms'] * 1e3:.3f} mm)" if e_fill.size else "")
                            + f"; a point for {figures['rows_left']:.1%} of the "
                            f"{n_left:,} rows where the left camera sees the line ({figures['rows_both']:.1%} of the "
                            f"{n_both:,} where both do)")
    return figures
