"""The rig checked against its own capture (issue 47): how well the rig file explains the decoded correspondences.

A camera pixel and the projector column and row decoded there are two rays that meet at the surface point when
the rig describes the capture. Each such pair is triangulated (the closest points of the two rays) and measured:

- ``median_px``: the distance, in projector pixels, between the decoded (column, row) and the projection of the
  camera ray's closest point into the projector: how far the decoded coordinates are from where the rig says
  that ray's light came from (decoding noise alone: a few tenths of a pixel);
- ``median_mm``: how far the two rays miss each other, millimetres.

For two cameras matched through the projector's codes (:func:`check_pair`), camera 1's pixel and camera 2's
matched position are the two rays: ``median_px`` is then the epipolar distance, how far camera 2's ray turns
out of the plane of camera 1's ray and the baseline, in camera-2 pixels (its focal length times the tangent of
that angle), and ``median_mm`` the rays' miss as above.

A capture that decodes columns only carries no check of the rig: every camera ray meets every column plane
(:attr:`RigCheck.checkable` False, said in its line). The figures are medians over at most :data:`SAMPLE`
pixels drawn evenly from the decoded ones, so a check costs milliseconds. :func:`ray_misses` is the check of any
correspondences and :func:`closest_points` its triangulation, which :mod:`rangekit.rig.refine` shares.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.camera import PinholeCamera

__all__ = ["POOR_FIT_PX", "SAMPLE", "RigCheck", "check_pair", "check_rig", "closest_points", "decoded_pairs",
           "ray_misses"]

#: Pixels sampled for the check.
SAMPLE = 20_000
#: A rig whose median miss in projector pixels is over this does not describe the capture well (decoding noise on
#: real captures is a few tenths of a pixel; the simulator's default rig: 0.1).
POOR_FIT_PX = 1.0


@dataclass(frozen=True)
class RigCheck:
    """How well a camera-projector rig explains a capture's decoded correspondences (module doc)."""

    n_pixels: int                     # decoded pixels with both coordinates (0: columns only, nothing to check)
    median_px: float                  # median projector-pixel distance of decoded and predicted (NaN: unchecked)
    median_mm: float                  # median miss of the camera and projector rays, millimetres (NaN: unchecked)
    p90_px: float = float("nan")
    pair: bool = False                # two cameras (epipolar distance in camera-2 pixels), not camera and projector

    @property
    def checkable(self) -> bool:
        return self.n_pixels > 0

    @property
    def fits(self) -> bool:
        return self.checkable and self.median_px <= POOR_FIT_PX

    def describe(self) -> str:
        """One line for people."""
        if not self.checkable:
            return ("rig check: none possible: the capture decodes projector columns only, and every camera ray "
                    "meets every column plane (code rows too to check the rig against the capture)")
        verdict = "fits the capture" if self.fits else (
            f"does NOT fit the capture (over {POOR_FIT_PX:g} px): check that the rig file belongs to this rig "
            "and that the camera has not moved")
        if self.pair:
            return (f"rig check: camera 2's matched points lie {self.median_px:.2f} px from camera 1's epipolar lines "
                    f"(median; 90% within {self.p90_px:.2f} px), the two cameras' rays miss by {self.median_mm:.3f} mm "
                    f"(median) over {self.n_pixels} pixels: it {verdict}")
        return (f"rig check: the rig predicts the decoded projector coordinates to {self.median_px:.2f} px "
                f"(median; 90% within {self.p90_px:.2f} px), the camera and projector rays miss by "
                f"{self.median_mm:.3f} mm (median) over {self.n_pixels} pixels: it {verdict}")


def check_rig(camera: PinholeCamera, projector: PinholeCamera, proj_col: np.ndarray,
              proj_row: np.ndarray | None, *, sample: int = SAMPLE) -> RigCheck:
    """The check of one capture: ``proj_col``, ``proj_row`` (H, W) decoded projector coordinates in
    ``projector``'s pixels (NaN where not decoded), ``camera`` the rig's camera of size (W, H)."""
    if proj_row is None or not np.any(np.isfinite(proj_row)):
        return RigCheck(0, float("nan"), float("nan"))
    uv_cam, uv_proj, n = decoded_pairs(proj_col, proj_row, sample=sample)
    if n == 0:
        return RigCheck(0, float("nan"), float("nan"))
    off_px, miss_mm, good = ray_misses(camera, projector, uv_cam, uv_proj)
    return _figures(n, off_px, miss_mm, good, pair=False)


def check_pair(first: PinholeCamera, second: PinholeCamera, x2: np.ndarray, y2: np.ndarray, *,
               sample: int = SAMPLE) -> RigCheck:
    """Two cameras: ``x2``, ``y2`` (H, W) over ``first``'s pixels, the position in ``second`` matched to each (NaN
    where none). ``median_px``: the epipolar distance in ``second``'s pixels (module doc)."""
    uv1, uv2, n = decoded_pairs(x2, y2, sample=sample)
    if n == 0:
        return RigCheck(0, float("nan"), float("nan"), pair=True)
    o1, d1 = first.rays(uv1)
    o2, d2 = second.rays(uv2)
    normal = np.cross(o2 - o1, d1)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    d2 = d2 / np.linalg.norm(d2, axis=1, keepdims=True)
    sin = np.abs(np.sum(normal * d2, 1))
    with np.errstate(divide="ignore", invalid="ignore"):
        epipolar_px = float(np.sqrt(second.K[0, 0] * second.K[1, 1])) * sin / np.sqrt(1 - sin ** 2)
    _, miss_mm, good = ray_misses(first, second, uv1, uv2)
    return _figures(n, epipolar_px, miss_mm, good, pair=True)


def decoded_pairs(u2: np.ndarray, v2: np.ndarray, *, sample: int = SAMPLE) -> tuple[np.ndarray, np.ndarray, int]:
    """((m, 2) first device's pixels, (m, 2) second's coordinates, how many pixels have both): ``u2``, ``v2`` (H, W)
    the second device's coordinates over the first's pixels, NaN where none; at most ``sample`` pixels, evenly."""
    ok = np.isfinite(u2) & np.isfinite(v2)
    ys, xs = np.nonzero(ok)
    if len(ys) == 0:
        return np.zeros((0, 2)), np.zeros((0, 2)), 0
    pick = np.linspace(0, len(ys) - 1, min(sample, len(ys))).round().astype(np.int64)
    ys, xs = ys[pick], xs[pick]
    return (np.column_stack([xs, ys]).astype(np.float64),
            np.column_stack([u2[ys, xs], v2[ys, xs]]).astype(np.float64), int(ok.sum()))


def closest_points(o1: np.ndarray, d1: np.ndarray, o2: np.ndarray, d2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where two sets of rays come closest: ``(s, t)``, (N,) each, such that ``o1 + s d1`` and ``o2 + t d2`` are
    the closest points of ray pairs (origins (N, 3) or (3,), directions (N, 3), any frame and unit; s, t in the
    directions' lengths). NaN or inf for parallel rays."""
    w = o1 - o2
    a, b, c = np.sum(d1 * d1, 1), np.sum(d1 * d2, 1), np.sum(d2 * d2, 1)
    d, e = np.sum(d1 * w, 1), np.sum(d2 * w, 1)
    den = a * c - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        return (b * e - c * d) / den, (a * e - b * d) / den


def ray_misses(first: PinholeCamera, second: PinholeCamera, uv_first: np.ndarray,
               uv_second: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The check of N correspondences, ``uv_first`` (N, 2) pixels of ``first`` and ``uv_second`` (N, 2) of
    ``second``: ``(off_px, miss_mm, good)``, (N,) each: the distance in ``second``'s pixels between ``uv_second``
    and the projection of the first ray's closest point, how far the two rays miss each other (millimetres), and
    where both are finite with the closest point in front of ``first``."""
    o1, d1 = first.rays(uv_first)
    o2, d2 = second.rays(uv_second)
    s, t = closest_points(o1, d1, o2, d2)
    p1, p2 = o1 + s[:, None] * d1, o2 + t[:, None] * d2
    miss_mm = np.linalg.norm(p1 - p2, axis=1) * 1e3
    off_px = np.linalg.norm(second.project(p1) - uv_second, axis=1)
    return off_px, miss_mm, np.isfinite(miss_mm) & np.isfinite(off_px) & (s > 0)


def _figures(n: int, off_px: np.ndarray, miss_mm: np.ndarray, good: np.ndarray, *, pair: bool) -> RigCheck:
    good = good & np.isfinite(off_px)
    if not good.any():
        return RigCheck(n, float("inf"), float("inf"), float("inf"), pair=pair)
    return RigCheck(n, float(np.median(off_px[good])), float(np.median(miss_mm[good])),
                    float(np.percentile(off_px[good], 90)), pair=pair)
