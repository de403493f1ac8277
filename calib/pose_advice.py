"""Where to put the calibration board next: the parts of the camera image and the tilts the kept poses have not
covered yet, as one sentence, and a picture of the tilts so far.

A good calibration sees corners all over the image (the lens distortion is fitted where corners are) and the board
tilted several ways (the focal length is fixed by foreshortening). :func:`next_pose_hint` names the emptiest ninth
of the image (:func:`rangekit.calib.pose_feedback.coverage_grid` summed over 3 x 3 zones) and the least used of four
tilt directions (the board's normal leaning left, right, up or down by more than :data:`TILT_COUNTED_DEG`);
:func:`tilt_image` draws each pose's normal as a dot on a disc whose rings are 20, 40 and 60 degrees of tilt.
"""

from __future__ import annotations

from typing import Sequence

import cv2
import numpy as np

from rangekit.calib.pose_feedback import coverage_grid

__all__ = ["TILT_COUNTED_DEG", "next_pose_hint", "tilt_image", "tilt_directions"]

#: A pose tilted less than this (degrees) counts as facing the camera, in none of the four directions.
TILT_COUNTED_DEG = 12.0
_ZONES = (("top left", "top", "top right"), ("left", "centre", "right"), ("bottom left", "bottom", "bottom right"))
# A board whose normal (its z axis, camera frame: x right, y down, z ahead) leans towards +x has its right edge
# further away: it is turned to the right, as a person holding it would say.
_DIRECTIONS = ("left", "right", "up", "down")


def tilt_directions(normals: Sequence[Sequence[float]]) -> np.ndarray:
    """(n, 4) bool: per pose, whether its board is tilted left, right, up, down (:data:`_DIRECTIONS`) by more
    than :data:`TILT_COUNTED_DEG`; ``normals``: per pose the board's z axis in the camera frame (unit)."""
    n = np.asarray(normals, np.float64).reshape(-1, 3)
    s = np.sin(np.radians(TILT_COUNTED_DEG))
    with np.errstate(invalid="ignore"):
        return np.stack([n[:, 0] < -s, n[:, 0] > s, n[:, 1] < -s, n[:, 1] > s], axis=1)


def next_pose_hint(kept: Sequence[tuple[np.ndarray, np.ndarray]], normals: Sequence[Sequence[float]],
                   size: tuple[int, int]) -> str:
    """One sentence: where to put the board next. ``kept``: per kept pose (ids (n,), uv (n, 2) camera pixels);
    ``normals``: per kept pose its board normal (camera frame); ``size``: (width, height) of the image."""
    counts = coverage_grid(kept, size)
    rows, cols = counts.shape
    zone = np.array([[counts[r * rows // 3:(r + 1) * rows // 3, c * cols // 3:(c + 1) * cols // 3].astype(bool).mean()
                      for c in range(3)] for r in range(3)])
    r, c = np.unravel_index(int(np.argmin(zone)), zone.shape)     # first of the emptiest, reading order
    used = tilt_directions(normals).sum(axis=0)
    direction = _DIRECTIONS[int(np.argmin(used))]
    if not len(kept):
        return f"put the board in the {_ZONES[1][1]} of the view, filling about a third of it, tilted {direction}"
    where = _ZONES[r][c]
    return (f"next: the board near the {where} of the view ({zone[r, c] * 100:.0f}% of that part covered), tilted "
            f"{direction} ({int(used.min())} of {len(kept)} poses so far)")


def tilt_image(normals: Sequence[Sequence[float]], accepted: Sequence[bool], side: int = 240) -> np.ndarray:
    """(side, side, 3) uint8 RGB: each pose's board normal as a dot (kept green, rejected red, the last one
    ringed), seen from the camera: the centre is a board facing it, rings at 20, 40 and 60 degrees of tilt."""
    img = np.full((side, side, 3), 30, np.uint8)
    c = (side - 1) / 2.0
    radius = 0.45 * side
    for deg in (20, 40, 60):
        cv2.circle(img, (int(round(c)), int(round(c))), int(round(radius * np.sin(np.radians(deg)) / np.sin(np.radians(60)))),
                   (80, 80, 80), 1, cv2.LINE_AA)
    cv2.line(img, (int(c), 4), (int(c), side - 5), (60, 60, 60), 1)
    cv2.line(img, (4, int(c)), (side - 5, int(c)), (60, 60, 60), 1)
    scale = radius / np.sin(np.radians(60))
    pts = np.asarray(normals, np.float64).reshape(-1, 3)
    for k, (normal, ok) in enumerate(zip(pts, accepted)):
        if not np.all(np.isfinite(normal)):
            continue
        p = (int(round(c + normal[0] * scale)), int(round(c + normal[1] * scale)))
        cv2.circle(img, p, 5, (60, 200, 90) if ok else (230, 50, 50), -1, cv2.LINE_AA)
        if k == len(pts) - 1:
            cv2.circle(img, p, 8, (255, 220, 0), 1, cv2.LINE_AA)
    return img
