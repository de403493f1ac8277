"""Two calibrated cameras matched through an uncalibrated projector's codes (issue 35; the layout of OpenCV's
structured-light point-cloud sample, ``pointcloud.cpp``).

Both cameras decode the projector's columns and rows (:func:`rangekit.coded.decode.decode`). A point of the
scene lit by projector pixel ``(c, r)`` is seen where each camera decodes ``(c, r)``: each pixel of camera 1 is
matched to the position in camera 2 where camera 2's codes equal camera 1's, and the two rays are
triangulated (midpoint of their common perpendicular, :func:`rangekit.coded.triangulate.triangulate_ray_ray`).
The projector's own lens and pose never enter.

Matching (:func:`code_positions`): camera 2's codes are inverted per projector pixel. Around each projector
pixel, the camera-2 pixels whose codes lie within ``reach`` pixels of it give a least-squares affine map
``(x, y) = A (c, r) + t``; its value at the pixel's code is where camera 2 sees it. Fits with fewer than 6
pixels, a degenerate spread of codes, or a residual over ``max_fit_rms`` camera pixels (two surfaces across a
depth edge) give no position. Camera 1's subpixel code is then looked up bilinearly between the four
projector pixels around it (:func:`match_codes`); OpenCV's sample instead matches whole projector pixels by
their cameras' mean positions, one point each.

The rig is checked against the matches (:func:`rangekit.rig.capture_check.check_pair`: the epipolar distance and
the rays' miss) for the cameras as given and exchanged (:func:`pair_cameras`): a capture whose files are named for
the other camera than the rig calls them is triangulated with the pairing that fits, and says so.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.coded.decode import decode
from rangekit.coded.patterns import PatternSpec
from rangekit.coded.result import DecodeResult
from rangekit.coded.triangulate import TriangulationResult, filter_range_map, triangulate_ray_ray
from rangekit.errors import ConfigError, DecodeError, naming
from rangekit.rig.capture_check import RigCheck, check_pair
from rangekit.surface.cloud import PointCloud

__all__ = ["PairMatch", "PairReconstruction", "code_positions", "match_codes", "match_pair", "pair_cameras", "pairings",
           "reconstruct_pair", "triangulate_pair"]

#: The exchanged pairing is taken when its epipolar distance is under this share of the given one's.
EXCHANGE_SHARE = 0.5


def _cell_moments(proj_col: np.ndarray, proj_row: np.ndarray, size: tuple[int, int]) -> dict:
    """Per projector pixel, the moments of the camera pixels decoding to it (codes relative to its centre)."""
    Wp, Hp = size
    ok = np.isfinite(proj_col) & np.isfinite(proj_row)
    ys, xs = np.nonzero(ok)
    c, r = proj_col[ok].astype(np.float64), proj_row[ok].astype(np.float64)
    ci, ri = np.rint(c).astype(np.int64), np.rint(r).astype(np.int64)
    inside = (ci >= 0) & (ci < Wp) & (ri >= 0) & (ri < Hp)
    ci, ri, c, r, xs, ys = ci[inside], ri[inside], c[inside], r[inside], xs[inside], ys[inside]
    dc, dr, x, y = c - ci, r - ri, xs.astype(np.float64), ys.astype(np.float64)
    cell = ri * Wp + ci
    values = {"n": None, "c": dc, "r": dr, "cc": dc * dc, "cr": dc * dr, "rr": dr * dr, "x": x, "y": y,
              "cx": dc * x, "rx": dr * x, "cy": dc * y, "ry": dr * y, "xx": x * x, "yy": y * y}
    return {k: np.bincount(cell, weights=v, minlength=Wp * Hp).astype(np.float64).reshape(Hp, Wp)
            for k, v in values.items()}


def _window(a: np.ndarray, along_c: np.ndarray, along_r: np.ndarray) -> np.ndarray:
    """out[j, i] = sum over the window of along_c[di] along_r[dj] a[j + dj, i + di] (zero outside)."""
    from scipy.ndimage import correlate1d

    return correlate1d(correlate1d(a, along_c, axis=1, mode="constant"), along_r, axis=0, mode="constant")


def code_positions(proj_col: np.ndarray, proj_row: np.ndarray, size: tuple[int, int], *, reach: int = 2,
                   max_fit_rms: float = 0.75) -> np.ndarray:
    """(Hp, Wp, 2) float64: the camera position (x, y), pixels, where each projector pixel's centre is seen.

    ``proj_col``, ``proj_row``: (H, W) a camera's decoded projector coordinates (NaN where none); ``size``: the
    projector's (width, height). NaN where no affine fit over the ``2 reach + 1`` square of projector pixels
    holds (module doc).
    """
    m = _cell_moments(proj_col, proj_row, size)
    one, ramp = np.ones(2 * reach + 1), np.arange(-reach, reach + 1, dtype=np.float64)
    box = {k: _window(v, one, one) for k, v in m.items()}
    # a neighbour's codes relative to this pixel are (c + di, r + dj): its moments shift with di, dj
    tot = dict(box)
    tot["c"] = box["c"] + _window(m["n"], ramp, one)
    tot["r"] = box["r"] + _window(m["n"], one, ramp)
    tot["cc"] = box["cc"] + 2 * _window(m["c"], ramp, one) + _window(m["n"], ramp ** 2, one)
    tot["cr"] = box["cr"] + _window(m["r"], ramp, one) + _window(m["c"], one, ramp) + _window(m["n"], ramp, ramp)
    tot["rr"] = box["rr"] + 2 * _window(m["r"], one, ramp) + _window(m["n"], one, ramp ** 2)
    for w in ("x", "y"):
        tot["c" + w] = box["c" + w] + _window(m[w], ramp, one)
        tot["r" + w] = box["r" + w] + _window(m[w], one, ramp)
    n = tot["n"]
    A = np.stack([np.stack([n, tot["c"], tot["r"]], -1), np.stack([tot["c"], tot["cc"], tot["cr"]], -1),
                  np.stack([tot["r"], tot["cr"], tot["rr"]], -1)], -2)                    # (Hp, Wp, 3, 3)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_c, mean_r = tot["c"] / n, tot["r"] / n
        var_c, var_r = tot["cc"] / n - mean_c ** 2, tot["rr"] / n - mean_r ** 2
        cov = tot["cr"] / n - mean_c * mean_r
        spread = (var_c * var_r - cov ** 2) > 0.05 ** 2                                  # codes not on a line
    good = (n >= 6) & spread
    out = np.full(n.shape + (2,), np.nan)
    if not np.any(good):
        return out
    Ag = A[good]
    for k, w in enumerate(("x", "y")):
        b = np.stack([tot[w], tot["c" + w], tot["r" + w]], -1)[good]
        coef = np.linalg.solve(Ag, b[..., None])[..., 0]
        sse = tot[w + w][good] - np.einsum("ij,ij->i", coef, b)                          # residual sum of squares
        fit = np.where(sse <= max_fit_rms ** 2 * n[good], coef[:, 0], np.nan)
        out[good, k] = fit
    return out


def match_codes(proj_col: np.ndarray, proj_row: np.ndarray, positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camera 2's (x, y) maps over camera 1's pixels: ``positions`` (:func:`code_positions` of camera 2) read
    bilinearly at camera 1's codes ``(proj_col, proj_row)``; NaN where a corner has no position."""
    Hp, Wp = positions.shape[:2]
    x2, y2 = np.full(proj_col.shape, np.nan), np.full(proj_col.shape, np.nan)
    ok = np.isfinite(proj_col) & np.isfinite(proj_row)
    c, r = proj_col[ok].astype(np.float64), proj_row[ok].astype(np.float64)
    c0, r0 = np.floor(c).astype(np.int64), np.floor(r).astype(np.int64)
    inside = (c0 >= 0) & (c0 < Wp - 1) & (r0 >= 0) & (r0 < Hp - 1)
    fc, fr = c - c0, r - r0
    c0, r0 = np.clip(c0, 0, Wp - 2), np.clip(r0, 0, Hp - 2)
    for k, out in enumerate((x2, y2)):
        p = positions[..., k]
        v = ((1 - fc) * (1 - fr) * p[r0, c0] + fc * (1 - fr) * p[r0, c0 + 1] + (1 - fc) * fr * p[r0 + 1, c0]
             + fc * fr * p[r0 + 1, c0 + 1])
        out[ok] = np.where(inside, v, np.nan)
    return x2, y2


@dataclass(frozen=True, eq=False)
class PairReconstruction:
    """Two cameras' capture under the same projector codes: each camera's decoding, camera 2's position of each
    camera-1 pixel, and the points, organised on camera 1's pixels (world frame, metres)."""

    decoded: tuple[DecodeResult, DecodeResult]
    match: tuple[np.ndarray, np.ndarray]   # (H1, W1) camera 2's x and y of each camera-1 pixel, NaN if none
    triangulated: TriangulationResult       # organised on camera 1, flying pixels and rays that miss removed
    cloud: PointCloud                       # valid points, coloured by camera 1's white frame, normals to it
    rig_check: RigCheck | None = None       # the pairing used, checked against the matches
    exchanged: bool = False                 # the first capture was camera 2's (the rig's cameras exchanged)
    cameras: tuple[PinholeCamera, PinholeCamera] | None = None   # the cameras triangulated with, first capture's first

    def pairing_line(self) -> str:
        """One line: which rig camera took which capture, and why."""
        if not self.exchanged:
            return "cameras: the first capture is the rig's camera 1, as named"
        return ("cameras EXCHANGED: the first capture's files are camera 2's (the rig's cameras fit the captures only "
                "the other way round); triangulated as such")

    def __repr__(self) -> str:
        return f"PairReconstruction({self.decoded[0]!r}, {self.cloud!r})"


@dataclass(frozen=True, eq=False)
class PairMatch:
    """Both cameras' decodings and camera 2's position of each first-capture pixel (:func:`match_pair`)."""

    decoded: tuple[DecodeResult, DecodeResult]
    x2: np.ndarray                          # (H1, W1) camera 2's x of each first-capture pixel, NaN if none
    y2: np.ndarray
    sizes: tuple[tuple[int, int], tuple[int, int]]   # each capture's (width, height)


def match_pair(stacks, spec: PatternSpec, *, subpixel: bool = True, min_confidence: float = 0.03,
               full_scale: float | None = None, decode_options: dict | None = None,
               sources=None) -> PairMatch:
    """Decode both captures (``stacks``: two stacks in ``spec``'s frame order) and match the first's pixels to the
    second's positions through the codes (module doc); the rig never enters. ``sources``: each capture's name
    (its folder), put in front of an error decoding it (a dark camera 2 is named as camera 2's folder);
    default "camera 1", "camera 2"."""
    if "rows" not in spec.axes or "columns" not in spec.axes:
        raise ConfigError(f"two cameras match through the projector's columns and rows; the {spec.method} "
                          f"capture codes only {', '.join(spec.axes)}")
    sizes = tuple((np.asarray(stack[0]).shape[1], np.asarray(stack[0]).shape[0]) for stack in stacks)
    decs = []
    for stack, source in zip(stacks, sources or ("camera 1", "camera 2")):
        with naming(source):
            dec = decode(stack, spec, subpixel=subpixel, full_scale=full_scale, **(decode_options or {}))
        weak = dec.confidence < min_confidence
        decs.append((dec, np.where(weak, np.nan, dec.proj_col), np.where(weak, np.nan, dec.proj_row)))
    (dec1, c1, r1), (dec2, c2, r2) = decs
    x2, y2 = match_codes(c1, r1, code_positions(c2, r2, (spec.width, spec.height)))
    return PairMatch((dec1, dec2), x2, y2, sizes)


def pairings(cameras: tuple[PinholeCamera, PinholeCamera],
             sizes) -> list[tuple[tuple[PinholeCamera, PinholeCamera], bool]]:
    """The ways ``cameras`` can have taken captures of ``sizes`` ((pair, exchanged), the rig's order first);
    ConfigError naming the sizes when neither can."""
    out = [((cameras[i], cameras[j]), (i, j) == (1, 0)) for i, j in ((0, 1), (1, 0))
           if cameras[i].size == tuple(sizes[0]) and cameras[j].size == tuple(sizes[1])]
    if not out:
        raise ConfigError(f"the captures are {sizes[0][0]}x{sizes[0][1]} and {sizes[1][0]}x{sizes[1][1]} but the rig's "
                          f"cameras {cameras[0].name!r} and {cameras[1].name!r} are {cameras[0].width}x"
                          f"{cameras[0].height} and {cameras[1].width}x{cameras[1].height}, either way round")
    return out


def reconstruct_pair(stacks, spec: PatternSpec, cameras: tuple[PinholeCamera, PinholeCamera], *,
                     subpixel: bool = True, max_jump: float = 0.004, max_residual: float = 0.002,
                     min_confidence: float = 0.03, edge_margin: int = 1, full_scale: float | None = None,
                     decode_options: dict | None = None) -> PairReconstruction:
    """Decode both cameras' captures (``stacks``: two stacks in ``spec``'s frame order) and triangulate camera
    1's pixels with camera 2's matching positions, the cameras paired as the matches say (:func:`pair_cameras`);
    filters as :func:`rangekit.coded.reconstruct.reconstruct_view` (``max_residual``: metres between the two
    rays)."""
    match = match_pair(stacks, spec, subpixel=subpixel, min_confidence=min_confidence, full_scale=full_scale,
                       decode_options=decode_options)
    options = pairings(cameras, match.sizes)
    used, checked, exchanged = pair_cameras([p for p, _ in options], match.x2, match.y2,
                                            exchanged=[e for _, e in options])
    return triangulate_pair(match, used, checked=checked, exchanged=exchanged, max_jump=max_jump,
                            max_residual=max_residual, edge_margin=edge_margin, full_scale=full_scale)


def triangulate_pair(match: PairMatch, cameras: tuple[PinholeCamera, PinholeCamera], *, checked: RigCheck | None = None,
                     exchanged: bool = False, max_jump: float = 0.004, max_residual: float = 0.002,
                     edge_margin: int = 1, full_scale: float | None = None) -> PairReconstruction:
    """``match`` triangulated with ``cameras`` (the first capture's camera first) and filtered."""
    dec1 = match.decoded[0]
    checked = checked if checked is not None else check_pair(cameras[0], cameras[1], match.x2, match.y2)
    tri = triangulate_ray_ray(cameras[0], cameras[1], match.x2, match.y2)
    xyz, normals = filter_range_map(tri.xyz, cameras[0].center, max_jump=max_jump, margin=edge_margin,
                                    extra_drop=~(tri.residual <= max_residual))
    valid = np.isfinite(xyz[:, :, 0])
    if not np.any(valid):
        raise DecodeError("no camera-1 pixel was matched in camera 2 and triangulated; check that both cameras see "
                          f"the projector's light on the object and the rig's second camera pose ({checked.describe()})")
    tri = TriangulationResult(xyz, np.where(valid, tri.residual, np.nan), "ray-ray")
    white = np.asarray(dec1.white, dtype=np.float32) / np.float32(full_scale or (255 if dec1.white.dtype == np.uint8
                                                                                  else 65535))
    colours = white[valid] if white.ndim == 3 else np.repeat(white[valid][:, None], 3, axis=1)
    n = np.where(np.isfinite(normals[valid]), normals[valid], 0.0)
    return PairReconstruction(match.decoded, (match.x2, match.y2), tri,
                              PointCloud(xyz[valid], np.clip(colours, 0, 1), n), checked, exchanged, cameras)


def pair_cameras(pairings: list[tuple[PinholeCamera, PinholeCamera]], x2: np.ndarray, y2: np.ndarray, *,
                 exchanged: list[bool]) -> tuple[tuple[PinholeCamera, PinholeCamera], RigCheck, bool]:
    """(the pairing to triangulate with, its check, whether it is the exchanged one): the first of ``pairings``
    (the rig's order, when its sizes allow) unless another's epipolar distance over the matches ``x2``, ``y2``
    (camera 2's position of each first-capture pixel) is under :data:`EXCHANGE_SHARE` of the first's."""
    checks = [check_pair(a, b, x2, y2) for a, b in pairings]
    best = 0
    for k in range(1, len(pairings)):
        if checks[k].median_px < EXCHANGE_SHARE * checks[best].median_px:
            best = k
    return pairings[best], checks[best], exchanged[best]
