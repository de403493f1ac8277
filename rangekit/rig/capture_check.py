"""The rig checked against its own capture (issue 47): how well the rig file explains the decoded correspondences.

A camera pixel and the projector column and row decoded there are two rays that meet at the surface point when
the rig describes the capture. Each such pair is triangulated (the closest points of the two rays) and measured:

- ``median_px``: the distance, in projector pixels, between the decoded (column, row) and the projection of the
  camera ray's closest point into the projector: how far the decoded coordinates are from where the rig says
  that ray's light came from (decoding noise alone: a few tenths of a pixel);
- ``median_mm``: how far the two rays miss each other, millimetres.

A capture that decodes columns only carries no check of the rig: every camera ray meets every column plane
(:attr:`RigCheck.checkable` False, said in its line). The figures are medians over at most :data:`SAMPLE`
pixels drawn evenly from the decoded ones, so a check costs milliseconds. :func:`ray_misses` is the check of any
correspondences (a second camera's too) and :func:`closest_points` its triangulation, which
:mod:`rangekit.rig.refine` shares.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.camera import PinholeCamera

__all__ = ["POOR_FIT_PX", "SAMPLE", "RigCheck", "check_rig", "closest_points", "ray_misses"]

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
        return (f"rig check: the rig predicts the decoded projector coordinates to {self.median_px:.2f} px "
                f"(median; 90% within {self.p90_px:.2f} px), the camera and projector rays miss by "
                f"{self.median_mm:.3f} mm (median) over {self.n_pixels} pixels: it {verdict}")


def check_rig(camera: PinholeCamera, projector: PinholeCamera, proj_col: np.ndarray,
              proj_row: np.ndarray | None, *, sample: int = SAMPLE) -> RigCheck:
    """The check of one capture: ``proj_col``, ``proj_row`` (H, W) decoded projector coordinates in
    ``projector``'s pixels (NaN where not decoded), ``camera`` the rig's camera of size (W, H)."""
    if proj_row is None or not np.any(np.isfinite(proj_row)):
        return RigCheck(0, float("nan"), float("nan"))
    ok = np.isfinite(proj_col) & np.isfinite(proj_row)
    ys, xs = np.nonzero(ok)
    if len(ys) == 0:
        return RigCheck(0, float("nan"), float("nan"))
    pick = np.linspace(0, len(ys) - 1, min(sample, len(ys))).round().astype(np.int64)
    ys, xs = ys[pick], xs[pick]
    uv_cam = np.column_stack([xs, ys]).astype(np.float64)
    uv_proj = np.column_stack([proj_col[ys, xs], proj_row[ys, xs]]).astype(np.float64)
    off_px, miss_mm, good = ray_misses(camera, projector, uv_cam, uv_proj)
    if not good.any():
        return RigCheck(int(len(ys)), float("inf"), float("inf"), float("inf"))
    return RigCheck(int(ok.sum()), float(np.median(off_px[good])), float(np.median(miss_mm[good])),
                    float(np.percentile(off_px[good], 90)))


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
