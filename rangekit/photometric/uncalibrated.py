"""Uncalibrated photometric stereo: rank-3 factorisation with shadows, then the integrability constraint
(Yuille & Snow 1997) fixes the ambiguity up to a generalised bas-relief transform."""

from __future__ import annotations

import numpy as np

from rangekit.errors import InputError
from rangekit.photometric.solve import (CHUNK, PhotometricResult, check_images, check_mask, grey_images, stack_pixels,
                                        to_maps, weighted_solve)

__all__ = ["uncalibrated_photometric_stereo"]


def _rank3_with_shadows(B: np.ndarray, W: np.ndarray, n_iterations: int = 30) -> tuple[np.ndarray, np.ndarray]:
    """Rank-3 ``B ~ X S`` ignoring entries with W = 0 (shadows), by alternating least squares."""
    U, s, Vt = np.linalg.svd(B * W, full_matrices=False)
    S = np.sqrt(s[:3])[:, None] * Vt[:3]
    X = None
    for _ in range(n_iterations):
        X = weighted_solve(B, W, S)
        X = np.nan_to_num(X)
        XX = (X[:, :, None] * X[:, None, :]).reshape(len(X), 9)
        M = (W.T @ XX).reshape(-1, 3, 3)
        rhs = (W * B).T @ X
        S = np.linalg.solve(M, rhs[:, :, None])[:, :, 0].T
    return X, S


def _integrability_gbr(E: np.ndarray) -> np.ndarray:
    """Yuille & Snow (1997): from a pseudo-normal field E (H, W, 3, NaN outside), find A0 (3, 3) such
    that ``A0^T e`` is integrable; the true field is ``M A0^T e`` for a GBR ``M`` (see below)."""
    ex = (np.roll(E, -1, axis=1) - np.roll(E, 1, axis=1)) / 2
    ey = (np.roll(E, -1, axis=0) - np.roll(E, 1, axis=0)) / 2
    ok = np.isfinite(ex).all(2) & np.isfinite(ey).all(2) & np.isfinite(E).all(2)
    ok[:, [0, -1]] = False
    ok[[0, -1], :] = False
    if np.count_nonzero(ok) < 6:  # six unknowns in theta below; fewer rows leave them undetermined
        raise InputError(f"mask: uncalibrated photometric stereo needs at least 6 mask pixels whose four "
                         f"neighbours are in the mask too (integrability), found {np.count_nonzero(ok)}")
    e, ex, ey = E[ok], ex[ok], ey[ok]
    pairs = [(0, 1), (0, 2), (1, 2)]
    Py = [e[:, i] * ey[:, j] - e[:, j] * ey[:, i] for i, j in pairs]
    Qx = [e[:, i] * ex[:, j] - e[:, j] * ex[:, i] for i, j in pairs]
    R = np.column_stack(Py + [-q for q in Qx])
    R /= np.maximum(np.linalg.norm(R, axis=1, keepdims=True), 1e-300)  # equal say per pixel
    theta = np.linalg.svd(R, full_matrices=False)[2][-1]
    P01, P02, P12, Q01, Q02, Q12 = theta
    c1 = np.array([P12, -P02, P01])   # = a3 x a1
    c2 = np.array([Q12, -Q02, Q01])   # = a3 x a2
    a3 = np.cross(c1, c2)
    n3 = a3 @ a3
    a1 = np.cross(c1, a3) / n3
    a2 = np.cross(c2, a3) / n3
    return np.column_stack([a1, a2, a3])


def uncalibrated_photometric_stereo(images, mask=None, *, shadow_threshold: float = 0.02,
                                    rng: int | np.random.Generator = 0,
                                    max_fit_pixels: int = 20000) -> PhotometricResult:
    """Photometric stereo with unknown lights of equal intensity.

    Steps: (1) rank-3 factorisation ``B ~ E S0`` (SVD, refined by alternating least squares that
    ignores entries darker than ``shadow_threshold`` times the pixel's brightest, i.e. shadows) on at
    most ``max_fit_pixels`` pixels, then every pixel's pseudo-normal against ``S0``; (2) Yuille & Snow
    integrability of the pseudo-normal field reduces the 3x3 ambiguity to the generalised bas-relief
    (GBR) ``Z -> lambda Z + mu x + nu y``; (3) the GBR parameters are fixed in closed form by requiring
    all lights to have the same norm (equal intensities: divide each image by its light intensity first
    if they differ); (4) the sign ambiguities are resolved so normals face the camera (``n_z < 0``)
    and the surface is convex (bulges towards the camera).

    Parameters
    ----------
    images : (f, H, W) or (f, H, W, 3) float ndarray
        Linear intensities (RGB is converted by :func:`rangekit.image.to_grey`), f >= 3 (f >= 6 for step 3).
    mask : (H, W) bool, optional
        Pixels to solve; should be a connected region with interior pixels (integrability uses
        central differences).

    Returns
    -------
    PhotometricResult
        ``lights`` (f, 3) are the estimated lights scaled to mean norm 1; albedo in the same scale.

    Raises
    ------
    InputError
        As :func:`photometric_stereo`, or fewer than 6 images.
    """
    images = check_images(images)
    f = images.shape[0]
    if f < 6:
        raise InputError(f"images: uncalibrated photometric stereo needs at least 6 images to fix the "
                         f"bas-relief ambiguity from equal light intensities, found {f}")
    mask = check_mask(mask, images.shape[1:3], images)
    B = stack_pixels(grey_images(images), mask).astype(np.float64)
    rng = np.random.default_rng(rng)
    W = (B > shadow_threshold * B.max(axis=1, keepdims=True)).astype(np.float64)
    sub = rng.choice(len(B), size=min(max_fit_pixels, len(B)), replace=False)
    spread = np.linalg.svd(B[sub], compute_uv=False)
    if len(spread) < 3 or not spread[2] > 1e-6 * spread[0]:
        raise InputError(f"images: the {f} images vary with the light in fewer than 3 independent ways over the "
                         f"{len(B)} masked pixels (rank {int(np.sum(spread > 1e-6 * spread[0]))} < 3); "
                         "uncalibrated photometric stereo needs lights from at least 3 directions, "
                         "not in one plane, and a curved surface")
    _, S0 = _rank3_with_shadows(B[sub], W[sub])
    X0 = np.empty((len(B), 3))
    for i in range(0, len(B), CHUNK):
        X0[i:i + CHUNK] = np.nan_to_num(weighted_solve(B[i:i + CHUNK], W[i:i + CHUNK], S0))
    # (2) integrability -> GBR
    E = np.full(mask.shape + (3,), np.nan)
    E[mask] = X0
    A0 = _integrability_gbr(E)
    X1 = X0 @ A0                      # rows b0 = A0^T e
    S1 = np.linalg.solve(A0, S0)      # columns s0 = A0^-1 s_hat
    # (3) GBR b = M b0, M = [[l, 0, -mu], [0, l, -nu], [0, 0, 1]]; s = M^-T s0 with |s| constant.
    # s^T s = s0^T D s0, D = M^-1 M^-T = [[(1+mu^2)/l^2, mu nu/l^2, mu/l], [., (1+nu^2)/l^2, nu/l], [., ., 1]]
    s0 = S1.T
    iu = np.triu_indices(3)
    A = np.column_stack([s0[:, i] * s0[:, j] * (1 if i == j else 2) for i, j in zip(*iu)])
    d = np.linalg.lstsq(A, np.ones(f), rcond=None)[0]
    D = np.zeros((3, 3))
    D[iu] = d
    D = D + D.T - np.diag(np.diag(D))
    D /= D[2, 2]
    inv_l2 = 0.5 * ((D[0, 0] - D[0, 2] ** 2) + (D[1, 1] - D[1, 2] ** 2))
    lam = 1.0 / np.sqrt(max(inv_l2, 1e-12))
    mu, nu = D[0, 2] * lam, D[1, 2] * lam
    M = np.array([[lam, 0.0, -mu], [0.0, lam, -nu], [0.0, 0.0, 1.0]])
    X = X1 @ M.T
    S = np.linalg.solve(M.T, S1)
    k = np.mean(np.linalg.norm(S, axis=0))
    X, S = X * k, S / k
    # (4) signs: normals face the camera, then convex (n points away from the centroid in x, y).
    if np.median(X[:, 2]) > 0:
        X, S = -X, -S
    vv, uu = np.nonzero(mask)
    if np.sum(X[:, 0] * (uu - uu.mean()) + X[:, 1] * (vv - vv.mean())) < 0:
        flip = np.array([-1.0, -1.0, 1.0])
        X, S = X * flip, S * flip[:, None]
    normals, albedo = to_maps(X, mask)
    return PhotometricResult(normals, albedo, mask, "uncalibrated", S.T.copy())
