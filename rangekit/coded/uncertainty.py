"""Per-point uncertainty of coded light: the decoder's noise model and its propagation through triangulation.

Image noise
-----------
A camera's noise grows with the signal (shot noise) on top of a floor (read noise, quantisation):
``var(I) = a + b I`` in raw digital numbers. Gray-code captures measure it without a model of the scene:
a pattern and its inverse add up to white + black in light (light adds linearly, whatever the blur), so
``D = P + P_inv - W - B`` is pure noise with ``var(D) = 4 a + 2 b (W + B)``. :func:`fit_noise_model`
fits ``a`` and ``b`` to the mean ``D**2`` in bins of ``W + B``.

Decoded coordinate
------------------
N-step phase shifting (``I_s = A + B cos(phi - 2 pi s / N) + n_s``, N >= 4 or any N with constant noise)
has ``std(phi) = sqrt(2 / N) sigma_I / B`` (sigma_I at the offset A: the signal-dependent part averages
out over the steps), and a period of T projector pixels turns it into ``std(u) = T / (2 pi) std(phi)``
(:func:`phase_coordinate_std`), times the slope of the projector-response correction where there is one.
Integer Gray codes are uniform within their stripe: ``1 / sqrt(12)`` projector pixels.

Propagation
-----------
Ray-plane: the point ``X = o + t d`` on the camera ray meets the light surface of column u, i.e.
``u(X) = u``; by the implicit-function theorem ``dt/du = 1 / (grad u(X) . d)``, with ``grad u`` the
projector's projection Jacobian (lens distortion included). Ray-ray: the midpoint of the common
perpendicular of the camera ray and the projector ray through (u, v); its derivative with respect to the
projector ray's direction comes from differentiating the 2x2 normal equations. Column and row errors are
independent, so ``sigma^2 = (dX/du . d)^2 std(u)^2 + (dX/dv . d)^2 std(v)^2`` along the unit camera ray d.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.camera import PinholeCamera, distort_jacobian, world_pixel_rays
from rangekit.errors import InputError
from rangekit.geometry import apply_T

__all__ = ["NoiseModel", "fit_noise_model", "phase_coordinate_std", "GRAY_CODE_STD", "along_ray_jacobian",
           "point_sigma"]

#: Std of an integer Gray-code column, projector pixels: the true column is uniform within the stripe.
GRAY_CODE_STD = float(1.0 / np.sqrt(12.0))


@dataclass(frozen=True)
class NoiseModel:
    """Camera noise ``var(I) = a + b I`` in raw digital numbers (I the noise-free signal)."""

    a: float  # DN^2: read noise and quantisation
    b: float  # DN: shot noise per DN of signal

    def std(self, signal: np.ndarray) -> np.ndarray:
        """Noise std (DN) at ``signal`` (DN), same shape, float32."""
        return np.sqrt(np.maximum(self.a + self.b * np.asarray(signal, dtype=np.float32), 1e-12)).astype(np.float32)


def fit_noise_model(signal: np.ndarray, variance: np.ndarray, *, ka: float = 1.0, kb: float = 1.0,
                    bins: int = 24) -> NoiseModel:
    """Fit :class:`NoiseModel` to per-pixel noise samples: ``E[variance] = ka a + kb b signal``.

    Parameters
    ----------
    signal, variance : (N,) samples (DN and DN^2): for Gray-code pairs ``signal = W + B`` and
        ``variance = (P + P_inv - W - B)**2`` with ka = 4, kb = 2 (module doc); for phase-shift residuals
        ``signal = A`` and ``variance`` a per-pixel noise estimate of the phase frames with ka = kb = 1.
    bins : quantile bins of ``signal``; the fit is weighted least squares on the bin means.

    Returns
    -------
    NoiseModel with ``a >= 0`` and ``b >= 0`` (too few samples: the mean variance as ``a``).
    """
    L = np.asarray(signal, dtype=np.float64).ravel()
    V = np.asarray(variance, dtype=np.float64).ravel()
    ok = np.isfinite(L) & np.isfinite(V)
    L, V = L[ok], V[ok]
    if L.size == 0:
        return NoiseModel(0.0, 0.0)
    flat = NoiseModel(max(float(V.mean()) / ka, 0.0), 0.0)
    if L.size < 20 * bins:
        return flat
    edges = np.quantile(L, np.linspace(0, 1, bins + 1))
    k = np.clip(np.searchsorted(edges, L, side="right") - 1, 0, bins - 1)
    n = np.bincount(k, minlength=bins).astype(np.float64)
    use = n > 0
    Lm = np.bincount(k, L, bins)[use] / n[use]
    Vm = np.bincount(k, V, bins)[use] / n[use]
    w = np.sqrt(n[use])
    a, b = np.linalg.lstsq(np.column_stack([np.full(Lm.size, ka), kb * Lm]) * w[:, None], Vm * w, rcond=None)[0]
    if b < 0:
        return flat
    if a < 0:
        return NoiseModel(0.0, float(np.sum(n[use] * Vm * Lm) / np.sum(n[use] * kb * Lm * Lm)))
    return NoiseModel(float(a), float(b))


def phase_coordinate_std(modulation: np.ndarray, offset: np.ndarray, noise: NoiseModel, steps: int,
                         period: float, slope: np.ndarray | float = 1.0) -> np.ndarray:
    """(H, W) float32 std of the projector coordinate (projector pixels) decoded by ``steps``-step phase
    shifting of ``period`` projector pixels, from the fringe ``modulation`` B and ``offset`` A (raw DN, as
    :func:`rangekit.coded.phase.phase_from_steps` returns them) and the camera ``noise``. ``slope``: the
    derivative of the response correction (true / measured phase), 1 without one. NaN where B <= 0."""
    B = np.asarray(modulation, dtype=np.float32)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = noise.std(offset) * np.float32(np.sqrt(2.0 / steps) * period / (2 * np.pi)) / B * np.abs(slope)
    return np.where(B > 0, s, np.nan).astype(np.float32)


def _projection_jacobian(projector: PinholeCamera, X: np.ndarray) -> np.ndarray:
    """(N, 2, 3) derivative of the projector pixel (u, v) with respect to the world point X (N, 3)."""
    R = projector.T_cam_world[:3, :3]
    P = apply_T(projector.T_cam_world, X)
    z = P[:, 2]
    xy = P[:, :2] / z[:, None]
    # d(x, y)/dP: [[1/z, 0, -x/z], [0, 1/z, -y/z]]
    dxy = np.zeros((len(X), 2, 3))
    dxy[:, 0, 0] = dxy[:, 1, 1] = 1.0 / z
    dxy[:, 0, 2] = -xy[:, 0] / z
    dxy[:, 1, 2] = -xy[:, 1] / z
    f = np.array([projector.K[0, 0], projector.K[1, 1]])
    return f[None, :, None] * (distort_jacobian(xy, projector.dist) @ dxy @ R)


def along_ray_jacobian(camera: PinholeCamera, projector: PinholeCamera, xyz: np.ndarray,
                       proj_row: np.ndarray | None = None, proj_col: np.ndarray | None = None, *,
                       proj_xy: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """Derivatives (metres per projector pixel) of each point's position along its unit camera ray with
    respect to its decoded projector column and row.

    Parameters
    ----------
    camera, projector : the calibrated devices (world frame).
    xyz : (H, W, 3) triangulated world points (NaN where invalid).
    proj_row, proj_col : (H, W) decoded projector coordinates; give both for a ray-ray triangulation
        (:func:`rangekit.coded.triangulate.triangulate_ray_ray`), neither for ray-plane.
    proj_xy : optional (H, W, 2) undistorted normalised projector coordinates of (proj_col, proj_row), as
        the ray-ray triangulation returns them (``TriangulationResult.proj_xy``): saves undoing the
        projector's distortion again.

    Returns
    -------
    (d_col, d_row) : (H, W) float64 each (d_row None for ray-plane); NaN where ``xyz`` is invalid.
    """
    xyz = np.asarray(xyz, dtype=np.float64)
    H, W = xyz.shape[:2]
    if xyz.shape != (camera.height, camera.width, 3):
        raise InputError(f"xyz has shape {xyz.shape}; camera {camera.name!r} is {camera.width}x{camera.height}, "
                         f"so it must be ({camera.height}, {camera.width}, 3)")
    valid = np.isfinite(xyz).all(axis=2)
    d_col = np.full((H, W), np.nan)
    d_row = None if proj_row is None else np.full((H, W), np.nan)
    if not np.any(valid):
        return d_col, d_row
    X = xyz[valid]
    d1 = world_pixel_rays(camera)[1][valid.ravel()]
    d1 /= np.linalg.norm(d1, axis=1, keepdims=True)
    if proj_row is None:
        du_dt = np.einsum("nj,nj->n", _projection_jacobian(projector, X)[:, 0], d1)
        with np.errstate(divide="ignore"):
            d_col[valid] = 1.0 / du_dt
        return d_col, d_row
    uv = np.column_stack([np.asarray(proj_col, np.float64)[valid], np.asarray(proj_row, np.float64)[valid]])
    xy = projector.pixels_to_normalized(uv) if proj_xy is None else np.asarray(proj_xy, np.float64)[valid]
    R = projector.T_world_cam[:3, :3]
    d2 = np.column_stack([xy, np.ones(len(xy))]) @ R.T          # unnormalised projector ray
    # d(x, y)/d(u, v) = inverse distortion Jacobian / focal lengths
    Jn = np.linalg.inv(distort_jacobian(xy, projector.dist)) / np.array([projector.K[0, 0], projector.K[1, 1]])
    w = camera.center - projector.center
    a12 = np.einsum("nj,nj->n", d1, d2)
    a22 = np.einsum("nj,nj->n", d2, d2)
    det = a22 - a12 * a12                                     # a11 = 1
    s = (a12 * (d2 @ w) - a22 * (d1 @ w)) / det
    t = ((d2 @ w) - a12 * (d1 @ w)) / det
    for k, out in ((0, d_col), (1, d_row)):
        delta = np.column_stack([Jn[:, 0, k], Jn[:, 1, k], np.zeros(len(xy))]) @ R.T
        e = np.einsum("nj,nj->n", d1, delta)
        # normal equations [[1, -a12], [-a12, a22]] [s, t] = [-d1.w, d2.w], differentiated along delta
        r1 = e * t
        r2 = (delta @ w) + e * s - 2 * np.einsum("nj,nj->n", d2, delta) * t
        ds = (a22 * r1 + a12 * r2) / det
        dt = (a12 * r1 + r2) / det
        out[valid] = 0.5 * (ds + dt * a12 + t * e)             # (ds d1 + dt d2 + t delta) / 2 . d1
    return d_col, d_row


def point_sigma(camera: PinholeCamera, projector: PinholeCamera, xyz: np.ndarray, col_std: np.ndarray,
                row_std: np.ndarray | None = None, proj_col: np.ndarray | None = None,
                proj_row: np.ndarray | None = None, *, proj_xy: np.ndarray | None = None,
                gains: np.ndarray | None = None) -> np.ndarray:
    """(H, W) float32 predicted std (metres) of each triangulated point along its camera ray.

    ``col_std`` / ``row_std``: (H, W) std of the decoded projector column / row (projector pixels, as
    :class:`rangekit.coded.result.DecodeResult` carries them). Give ``row_std``, ``proj_col`` and
    ``proj_row`` for a ray-ray triangulation (and its ``proj_xy``, see :func:`along_ray_jacobian`); leave
    them out for ray-plane. ``gains``: the ray-ray triangulation's (H, W, 2) derivatives
    (``TriangulationResult.gains``, computed in its compiled pass), which saves :func:`along_ray_jacobian`.
    NaN where a point or a std is missing.
    """
    ray_ray = proj_row is not None
    if ray_ray and gains is not None:
        xyz = np.asarray(xyz, dtype=np.float64)
        if xyz.shape != (camera.height, camera.width, 3) or np.shape(gains) != xyz.shape[:2] + (2,):
            raise InputError(f"xyz has shape {xyz.shape} and gains {np.shape(gains)}; camera {camera.name!r} is "
                             f"{camera.width}x{camera.height}, so they must be ({camera.height}, {camera.width}, 3)"
                             f" and ({camera.height}, {camera.width}, 2)")
        invalid = ~np.isfinite(xyz).all(axis=2)
        g_col = np.where(invalid, np.nan, gains[:, :, 0])
        g_row = gains[:, :, 1]
    else:
        g_col, g_row = along_ray_jacobian(camera, projector, xyz, proj_row if ray_ray else None,
                                          proj_col if ray_ray else None, proj_xy=proj_xy if ray_ray else None)
    var = (g_col * np.asarray(col_std, np.float64)) ** 2
    if ray_ray:
        var = var + (g_row * np.asarray(row_std, np.float64)) ** 2
    return np.sqrt(var).astype(np.float32)
