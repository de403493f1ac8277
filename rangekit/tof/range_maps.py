"""Range maps in space: radial range to camera-frame depth and to points, and the two mixed-pixel filters
(flying pixels between two surfaces, partially covered pixels that report a surface their centre misses).

A ToF camera measures radial distance along each pixel's ray, not ``z``; the rays are
:func:`rangekit.camera.pixel_rays` (lens distortion undone exactly)."""

from __future__ import annotations

import math

import numpy as np

from rangekit.camera import PinholeCamera, pixel_rays
from rangekit.errors import InputError
from rangekit.geometry import apply_T

__all__ = ["range_to_depth", "depth_to_range", "range_to_points", "flying_pixels", "partial_pixels"]


def _check_range_map(range_map, camera: PinholeCamera, where: str) -> np.ndarray:
    r = np.asarray(range_map, dtype=np.float64)
    if r.shape != (camera.height, camera.width):
        raise InputError(f"{where}: range map is {r.shape[1] if r.ndim == 2 else '?'}x"
                         f"{r.shape[0] if r.ndim >= 1 else '?'} (shape {r.shape}) but camera {camera.name!r} is "
                         f"{camera.width}x{camera.height}")
    return r


def range_to_depth(range_map, camera: PinholeCamera) -> np.ndarray:
    """(H, W) camera-frame z in metres from radial distances along each pixel's ray (NaN stays NaN).

    ``z = r * d_z`` with ``d`` the unit ray of the pixel centre, lens distortion undone exactly.
    """
    r = _check_range_map(range_map, camera, "range_to_depth")
    return r * pixel_rays(camera)[..., 2]


def depth_to_range(depth_map, camera: PinholeCamera) -> np.ndarray:
    """(H, W) radial distance along each pixel's ray in metres from camera-frame z (NaN stays NaN): the inverse of
    :func:`range_to_depth`, ``r = z / d_z`` (a depth camera's map as a range map)."""
    z = _check_range_map(depth_map, camera, "depth_to_range")
    return z / pixel_rays(camera)[..., 2]


def range_to_points(range_map, camera: PinholeCamera, *, frame: str = "world") -> np.ndarray:
    """(H, W, 3) points in metres, NaN where the range is NaN, in the ``"camera"`` or ``"world"`` frame
    (``camera.T_world_cam``)."""
    if frame not in ("camera", "world"):
        raise InputError(f"range_to_points: frame must be 'camera' or 'world', found {frame!r}")
    r = _check_range_map(range_map, camera, "range_to_points")
    p = r[..., None] * pixel_rays(camera)
    if frame == "world" and not np.array_equal(camera.T_world_cam, np.eye(4)):
        p = apply_T(camera.T_world_cam, p.reshape(-1, 3)).reshape(p.shape)
    return p


def flying_pixels(range_map, camera: PinholeCamera, *, max_angle: float = math.radians(15.0)) -> np.ndarray:
    """(H, W) bool: mixed ("flying") pixels at depth edges.

    A pixel that averages a foreground and a background surface lands between them on its ray, so the
    3D vectors to its neighbours on *both* sides (left and right, or above and below, or either
    diagonal pair) run nearly along the ray. A pixel is flagged when, for some neighbour pair, both
    vectors make less than ``max_angle`` (radians) with the ray. A true edge pixel has one such neighbour
    only, and is kept; so is a surface seen at up to ``pi / 2 - max_angle`` of incidence.
    Pixels with NaN neighbours on both sides are not judged.
    """
    r = _check_range_map(range_map, camera, "flying_pixels")
    d = pixel_rays(camera)
    p = r[..., None] * d
    H, W = r.shape
    pad = np.pad(p, ((1, 1), (1, 1), (0, 0)), constant_values=np.nan)
    cos_max = math.cos(max_angle)

    def along_ray(dy: int, dx: int) -> np.ndarray:
        q = pad[1 + dy: 1 + dy + H, 1 + dx: 1 + dx + W] - p
        with np.errstate(invalid="ignore", divide="ignore"):
            c = np.abs(np.einsum("ijk,ijk->ij", q, d)) / np.linalg.norm(q, axis=2)
        return c > cos_max  # NaN compares False

    flagged = np.zeros((H, W), dtype=bool)
    for dy, dx in ((0, 1), (1, 0), (1, 1), (1, -1)):
        flagged |= along_ray(dy, dx) & along_ray(-dy, -dx)
    return flagged & np.isfinite(r)


def _neighbours(a: np.ndarray, fill):
    """The 8 neighbour maps of ``a`` (H, W), ``fill`` outside the image."""
    H, W = a.shape
    pad = np.pad(a, 1, constant_values=fill)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dy or dx:
                yield pad[1 + dy: 1 + dy + H, 1 + dx: 1 + dx + W]


def partial_pixels(range_map, amplitude, *, min_fill: float = 0.5, edge: float = 0.05) -> np.ndarray:
    """(H, W) bool: pixels at a depth edge that the surface they report covers only partly.

    A pixel straddling a depth edge sums the light of both surfaces, and the returned light falls as
    ``1 / r^2``: when the near surface covers part of the pixel it outshines the far one (by 50x for
    1 m against 7 m) and the pixel measures the near range, consistently at every frequency, so neither
    the unwrapping residual nor :func:`flying_pixels` sees anything wrong. But its centre ray, the
    direction the range is reported along, may see the far surface. The tell is the brightness
    ``A r^2`` (amplitude times range squared: albedo x incidence x covered fraction, the same along one
    surface): such a pixel is dimmer than the fully covered pixels of the surface it reports.

    Parameters
    ----------
    range_map : (H, W) metres (NaN where unknown).
    amplitude : (H, W) or (F, H, W) modulation amplitude (any units; averaged over frequencies).
    min_fill : flag a pixel whose brightness is below ``min_fill`` times the brightest neighbour on the
        same surface. 0.5 means "the reported surface covers less than half of the pixel": then the pixel
        centre is, for a straight edge, on the other surface.
    edge : a neighbour is on the same surface when its range is within ``edge`` x range (5%); a pixel is
        only judged when some neighbour in the image is not (a depth edge, or no range).

    Pixels with no neighbour on their surface are not judged; the image border is not an edge.
    """
    r = np.asarray(range_map, dtype=np.float64)
    A = np.asarray(amplitude, dtype=np.float64)
    if A.ndim == 3:
        A = A.mean(axis=0)
    if A.shape != r.shape:
        raise InputError(f"partial_pixels: amplitude is {A.shape}, range map {r.shape}; expected the same (H, W)")
    b = A * r ** 2
    at_edge = np.zeros(r.shape, dtype=bool)
    ref = np.full(r.shape, -np.inf)
    with np.errstate(invalid="ignore"):
        for rn, bn, inside in zip(_neighbours(r, np.nan), _neighbours(b, np.nan),
                                  _neighbours(np.ones(r.shape, bool), False)):
            same = np.abs(rn - r) <= edge * r  # NaN compares False
            at_edge |= inside & ~same          # the image border is not a depth edge
            ref = np.where(same, np.fmax(ref, bn), ref)
        return at_edge & (b < min_fill * ref) & np.isfinite(r)
