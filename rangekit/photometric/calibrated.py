"""Calibrated photometric stereo (Fusiello sec. 13.4): known lights, least squares or robust per pixel."""

from __future__ import annotations

import numpy as np

from rangekit.errors import InputError
from rangekit.photometric.solve import (PhotometricResult, check_images, check_lights, check_mask, grey_images,
                                        solve_chunks, stack_pixels, to_maps)

__all__ = ["photometric_stereo"]


def photometric_stereo(images, lights, mask=None, *, method: str = "ls",
                       channels: str = "grey") -> PhotometricResult:
    """Calibrated photometric stereo (Fusiello sec. 13.4): solve ``min ||B - X S||`` per pixel.

    Parameters
    ----------
    images : (f, H, W) or (f, H, W, 3) float ndarray
        Linear intensities, one image per light, each divided by its light's intensity. f >= 3.
    lights : (f, 3) float
        Unit light directions in the camera frame, from the surface towards the light.
    mask : (H, W) bool, optional
        Pixels to solve; default every pixel that is non-zero in some image.
    method : {"ls", "robust"}
        ``"ls"``: plain least squares, exact for Lambertian pixels lit by every light.
        ``"robust"``: trimmed start then shadow-aware IRLS with Tukey weights (see :func:`_robust_solve`),
        then the light a concave object reflects onto itself, measured in its cast shadows, removed and
        the fit repeated, where the shadows show its model holds (:mod:`rangekit.photometric.cavity_light`;
        ``interreflection`` in the result says which); use it when shadows, specular highlights or
        interreflections are present.
    channels : {"grey", "per-channel"}
        For RGB input: solve the grey image (:func:`rangekit.image.to_grey`), or each channel (normals from the summed
        albedo-scaled normals, albedo (H, W, 3) per channel).

    Returns
    -------
    PhotometricResult

    Raises
    ------
    InputError
        Fewer than 3 images, images of different sizes, lights not (f, 3) or not unit length, an empty
        mask, NaN in masked pixels, or an unknown ``method``/``channels``.
    """
    if method not in ("ls", "robust"):
        raise InputError(f"method: expected 'ls' or 'robust', found {method!r}")
    if channels not in ("grey", "per-channel"):
        raise InputError(f"channels: expected 'grey' or 'per-channel', found {channels!r}")
    images = check_images(images)
    L = check_lights(lights, images.shape[0])
    mask = check_mask(mask, images.shape[1:3], images)
    S = L.T
    if images.ndim == 4 and channels == "per-channel":
        B = stack_pixels(images, mask)                         # (p, f, 3)
        solved = [solve_chunks(B[:, :, c], S, method) for c in range(3)]
        Gc = np.stack([G for G, _ in solved], axis=2)  # (p, 3, 3)
        notes = [f"{name}: {found.describe()}" for name, (_, found) in zip("RGB", solved) if found is not None]
        normals, _ = to_maps(np.nansum(Gc, axis=2), mask)
        albedo = np.full(mask.shape + (3,), np.nan)
        albedo[mask] = np.einsum("pic,pi->pc", Gc, normals[mask])
    else:
        G, found = solve_chunks(stack_pixels(grey_images(images), mask), S, method)
        notes = [found.describe()] if found is not None else []
        normals, albedo = to_maps(G, mask)
    return PhotometricResult(normals, albedo, mask, method, L.copy(), "; ".join(notes))
