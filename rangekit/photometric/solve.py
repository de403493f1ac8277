"""The per-pixel Lambertian solve shared by calibrated and uncalibrated photometric stereo: the result type,
input checks, and batched least squares on (p, f) intensities (module doc of :mod:`rangekit.photometric`)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit._runtime.arguments import as_array
from rangekit.errors import InputError, shown
from rangekit.image import to_grey
from rangekit.photometric.cavity_light import CavityLight, cavity_light

__all__ = ["PhotometricResult"]

CHUNK = 32768  # pixels per batch: bounds memory to ~CHUNK * f * 8 bytes per temporary


@dataclass(frozen=True, eq=False)
class PhotometricResult:
    """Normals and albedo recovered by photometric stereo.

    Attributes
    ----------
    normals : (H, W, 3) float64
        Unit normals in the camera frame, facing the camera (``n_z < 0``); NaN outside ``mask`` and
        where the pixel could not be solved (fewer than 3 usable lights).
    albedo : (H, W) float64, or (H, W, 3) for ``channels="per-channel"``
        Lambertian albedo in the units of the input intensities divided by light intensity; NaN outside.
        For uncalibrated input it is known up to one global scale (lights are scaled to mean norm 1).
    mask : (H, W) bool
        Pixels that were solved.
    method : str
        ``"ls"``, ``"robust"`` or ``"uncalibrated"``.
    lights : (f, 3) float64
        The lights used (calibrated) or estimated (uncalibrated; direction times relative intensity).
    interreflection : str
        ``"robust"``: whether a concave object's interreflection was removed, and the figures that decided
        it (:mod:`rangekit.photometric.cavity_light`); "" for the other methods.
    """

    normals: np.ndarray
    albedo: np.ndarray
    mask: np.ndarray
    method: str
    lights: np.ndarray
    interreflection: str = ""

    def __repr__(self) -> str:
        H, W = self.mask.shape
        return (f"PhotometricResult(method={self.method!r}, size={W}x{H}, pixels={int(self.mask.sum())}, "
                f"lights={len(self.lights)}, median_albedo={float(np.nanmedian(self.albedo)):.4g})")


# ----------------------------------------------------------------------------------------------
# Input checks


def check_images(images) -> np.ndarray:
    arr = np.asarray(images) if not isinstance(images, (list, tuple)) else None
    if arr is None:
        shapes = {np.shape(im) for im in images}
        if len(shapes) > 1:
            raise InputError(f"images: all images must have the same size, found shapes {sorted(shapes)}")
        arr = np.asarray(images)
    if arr.ndim not in (3, 4) or (arr.ndim == 4 and arr.shape[3] != 3):
        raise InputError(f"images: expected (f, H, W) or (f, H, W, 3), found shape {arr.shape}")
    if arr.shape[0] < 3:
        raise InputError(f"images: photometric stereo needs at least 3 images (lights), found {arr.shape[0]}")
    if not np.issubdtype(arr.dtype, np.floating):
        arr = arr.astype(np.float32)
    return arr


def check_mask(mask, shape: tuple[int, int], images: np.ndarray) -> np.ndarray:
    if mask is None:
        m = np.any(images.reshape(images.shape[0], *shape, -1) > 0, axis=(0, 3))
    else:
        m = np.asarray(mask, dtype=bool)
        if m.shape != shape:
            raise InputError(f"mask: expected shape {shape} (H, W) like the images, found {m.shape}")
    if not m.any():
        raise InputError("mask: no pixel selected (mask is empty or every image is black); "
                         "pass a mask with at least one True pixel")
    return m


def check_lights(lights, f: int) -> np.ndarray:
    L = as_array("lights", lights, f"a ({f}, 3) array of unit directions")
    if L.shape != (f, 3):
        raise InputError(f"lights: expected shape ({f}, 3) (one unit direction per image), found {L.shape}")
    if not np.all(np.isfinite(L)):
        raise InputError(f"lights: rows {shown(np.flatnonzero(~np.isfinite(L).all(1)))} contain NaN/inf")
    norms = np.linalg.norm(L, axis=1)
    bad = np.flatnonzero(np.abs(norms - 1.0) > 1e-3)
    if bad.size:
        raise InputError(f"lights: rows {bad[:10].tolist()} are not unit length (norms "
                         f"{np.round(norms[bad[:10]], 4).tolist()}); pass directions L / |L| and divide "
                         f"each image by its light intensity instead")
    return L


def stack_pixels(images: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """(f, H, W[, 3]) -> (p, f[, 3]) masked pixels, with a NaN check and a check that some light arrived."""
    B = np.moveaxis(images[:, mask], 0, 1)
    if not np.all(np.isfinite(B)):
        n = int((~np.isfinite(B)).any(axis=tuple(range(1, B.ndim))).sum())
        raise InputError(f"images: {n} masked pixels contain NaN/inf; remove them from the mask "
                         f"(e.g. mask &= np.isfinite(images).all(axis=0))")
    if not np.any(B > 0):  # every normal would be 0/0: NaN maps that look like a result
        raise InputError(f"images: all {B.shape[1]} images are black (no value > 0) in the {B.shape[0]} masked "
                         "pixels: the images carry no light; expected images of the object lit by each light")
    return B


def grey_images(images: np.ndarray) -> np.ndarray:
    """(f, H, W, 3) RGB -> (f, H, W) grey by :func:`rangekit.image.to_grey` (the mean of the channels);
    (f, H, W) is returned as is. The caller divides each channel by its light intensity first."""
    return to_grey(images) if images.ndim == 4 else images


# ----------------------------------------------------------------------------------------------
# Per-pixel solvers on (p, f) intensities; S is (3, f)


def weighted_solve(B: np.ndarray, W: np.ndarray | None, S: np.ndarray) -> np.ndarray:
    """Solve ``min_g sum_k w_k (b_k - g . s_k)^2`` for every row of B; returns (p, 3), NaN if singular."""
    SS = (S[:, None, :] * S[None, :, :]).reshape(9, -1).T  # (f, 9) outer products s s^T
    if W is None:
        return np.linalg.lstsq(S.T, B.T, rcond=None)[0].T
    M = (W @ SS).reshape(-1, 3, 3)          # (p, 3, 3) = S diag(w) S^T
    rhs = (W * B) @ S.T                      # (p, 3)
    # Singular systems (fewer than 3 independent lights kept) give NaN, not an exception.
    det = np.linalg.det(M)
    scale = np.einsum("pii->p", M) ** 3
    ok = np.abs(det) > 1e-9 * np.maximum(scale, 1e-300)
    G = np.full((len(B), 3), np.nan)
    if ok.any():
        G[ok] = np.linalg.solve(M[ok], rhs[ok][:, :, None])[:, :, 0]
    return G


def _robust_solve(B: np.ndarray, S: np.ndarray, *, dark_fraction: float = 0.4,
                  bright_fraction: float = 0.3, n_iterations: int = 8, c_bright: float = 2.5,
                  c_dark: float = 4.685) -> tuple[np.ndarray, np.ndarray]:
    """Shadow- and highlight-robust per-pixel fit; returns (p, 3) albedo-scaled normals and the (p, f)
    observations found in cast shadow (predicted clearly lit, observed under half the prediction, weight 0).

    1. Trimmed start: per pixel drop the darkest ``dark_fraction`` (attached/cast shadows) and the
       brightest ``bright_fraction`` (highlights) observations and solve least squares.
    2. IRLS with a shadow-aware model: observations the current fit predicts in attached shadow
       (``g . s <= 0``) are left out (the linear model does not hold there); the rest get Tukey bisquare
       weights on their residual scaled by a per-pixel MAD (tighter, ``c_bright``, for brighter-than-model
       observations, since highlights only add light), so highlights and cast shadows fall out.
    """
    p, f = B.shape
    order = np.sort(B, axis=1)
    lo = order[:, min(int(dark_fraction * f), f - 3)][:, None]
    hi = order[:, max(f - 1 - int(bright_fraction * f), 2)][:, None]
    W = ((B >= lo) & (B <= hi)).astype(np.float64)
    G = weighted_solve(B, W, S)
    G0 = G
    for _ in range(n_iterations):
        pred = np.nan_to_num(G) @ S                   # (p, f)
        lit = pred > 1e-6 * np.linalg.norm(np.nan_to_num(G), axis=1, keepdims=True)
        r_signed = B - pred
        r = np.abs(r_signed)
        # Per-pixel MAD over lit observations: sort with unlit set to +inf, take the middle lit one.
        r_lit = np.where(lit, r, np.inf)
        r_sorted = np.sort(r_lit, axis=1)
        n_lit = lit.sum(axis=1)
        mad = np.take_along_axis(r_sorted, np.maximum(n_lit // 2, 0)[:, None], axis=1)[:, 0]
        level = np.max(pred, axis=1)  # the pixel's brightest predicted intensity
        sigma = np.maximum(1.4826 * np.where(np.isfinite(mad), mad, 0.0), 2e-3 * np.maximum(level, 1e-12))
        u = r / (np.where(r_signed > 0, c_bright, c_dark) * sigma[:, None])
        W = np.where(lit & (u < 1.0), (1.0 - u * u) ** 2, 0.0)
        G_new = weighted_solve(B, W, S)
        G = np.where(np.isfinite(G_new), G_new, G)
    G = np.where(np.isfinite(G), G, G0)
    pred = np.nan_to_num(G) @ S
    # Cast shadows: lights the fit puts clearly in front of the surface that left under half the light.
    shadow = (pred > 0.1 * np.linalg.norm(np.nan_to_num(G), axis=1, keepdims=True)) & (B < 0.5 * pred) & (W == 0)
    return G, shadow


def solve_chunks(B: np.ndarray, S: np.ndarray, method: str, *, global_rounds: int = 3,
                 force_cavity: bool = False) -> tuple[np.ndarray, CavityLight | None]:
    """(p, 3) albedo-scaled normals of (p, f) intensities B under lights S (3, f), and for ``"robust"`` what
    was found of a concave object's interreflection (None for ``"ls"``).

    ``"robust"`` then measures the light each image adds in proportion to the albedo in the cast shadows
    (:func:`rangekit.photometric.cavity_light.cavity_light`) and, only if its spherical-cavity model is
    seen to hold (``force_cavity``: whenever it can be measured, for comparisons), removes it and fits
    again, ``global_rounds`` times.
    """
    def robust(B_: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        G_, sh = np.empty((len(B_), 3)), np.zeros(B_.shape, dtype=bool)
        for i in range(0, len(B_), CHUNK):
            G_[i:i + CHUNK], sh[i:i + CHUNK] = _robust_solve(np.asarray(B_[i:i + CHUNK], dtype=np.float64), S)
        return G_, sh

    if method == "ls":
        out = np.empty((len(B), 3))
        for i in range(0, len(B), CHUNK):
            out[i:i + CHUNK] = weighted_solve(np.asarray(B[i:i + CHUNK], dtype=np.float64), None, S)
        return out, None
    G, shadow = robust(B)
    found = None
    for _ in range(global_rounds):
        again = cavity_light(B, np.nan_to_num(np.linalg.norm(G, axis=1)), shadow, S,
                             force=force_cavity)
        if not again.applied:   # the first round decides; a later one that no longer sees it keeps the last
            found = found or again
            break
        found = again
        G, shadow = robust(np.asarray(B, dtype=np.float64)
                           - np.linalg.norm(np.nan_to_num(G), axis=1)[:, None] * found.beta[None])
    return G, found


def to_maps(G: np.ndarray, mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    H, W = mask.shape
    rho = np.linalg.norm(G, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        n = G / rho[:, None]
    normals = np.full((H, W, 3), np.nan)
    normals[mask] = n
    albedo = np.full((H, W), np.nan)
    albedo[mask] = rho
    return normals, albedo
