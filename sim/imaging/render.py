"""Image formation: what the simulated camera records for a projected image.

For each camera pixel that sees a surface (ground truth from :mod:`rangekit.sim.scene.raycast`)::

    E = gain * [ L(col, row) * (albedo * cos_i + k_s (n.h)^shininess) * (ref_distance / d_proj)^2
                 + albedo * ambient
                 + albedo * global_fraction * mean(L) ]

* ``L`` is the projected radiance: pattern value p in [0, 1] through the projector response
  ``black_level + (1 - black_level) * p ** gamma``, blurred by the projector's defocus (Gaussian,
  ``projector_blur`` projector pixels), sampled bilinearly at the exact projector coordinate of the hit.
* ``E`` is in fractions of the camera's full scale; then the camera lens blurs it (Gaussian,
  ``camera_blur`` camera pixels), the sensor (:mod:`rangekit.sim.imaging.sensor`: exposure and ISO scale it,
  at the reference controls E is unscaled) adds shot noise (``E * full_well`` electrons, Poisson,
  drawn as its normal approximation with the same mean and variance) and Gaussian read noise
  (``read_noise`` electrons RMS), and the ADC clips and rounds to ``bits`` bits.
* The global term models interreflection and subsurface light, whether or not the projector lights the
  point directly: with ``global_blur = 0``, ``albedo * global_fraction * mean(L)`` (uniform); with
  ``global_blur > 0`` camera pixels, ``global_fraction`` times the direct light averaged over the
  surrounding surface with a Gaussian of that sigma, so it follows coarse patterns but not fine ones
  (what breaks coarse Gray-code bits under interreflection, Gupta & Nayar 2011).

The geometry does not depend on the pattern: :class:`ViewRenderer` precomputes every per-pixel factor
once per view, so a pattern costs one bilinear gather, two blurs and the noise.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass

import cv2
import numpy as np

from rangekit._runtime.executor import worker_count
from rangekit.errors import InputError, PatternError
from rangekit.sim.imaging._kernels import add_direct
from rangekit.sim.scene.raycast import ViewGeometry
from rangekit.sim.imaging.sensor import Exposure, digitise

__all__ = ["ImagingModel", "ViewRenderer"]


@dataclass(frozen=True)
class ImagingModel:
    """Parameters of the simulated projector response and camera sensor. Defaults: a realistic rig."""

    gain: float = 1.0              # full-scale fraction from white light on albedo 1, facing, at ref_distance,
                                   # at the reference controls CameraControls() (33333 us, ISO 100; sim/imaging/sensor.py)
    ref_distance: float = 0.5      # metres; projector irradiance falls off as (ref_distance / d)^2
    ambient: float = 0.01          # room light, as a fraction of the projector's white
    global_fraction: float = 0.0   # global light: fraction of the (local) direct light added everywhere
    global_blur: float = 0.0       # camera px; 0: global light from the mean projected radiance (uniform),
                                   # > 0: from the direct light blurred over this Gaussian sigma (interreflection)
    gamma: float = 2.2             # projector response exponent (1 = linear)
    black_level: float = 0.001     # projector light leak at pattern value 0 (contrast 1000:1)
    projector_blur: float = 0.5    # projector defocus, Gaussian sigma in projector pixels (0 = sharp)
    camera_blur: float = 0.5       # camera lens PSF, Gaussian sigma in camera pixels (0 = sharp)
    full_well: float = 10000.0     # electrons at full scale (shot noise); 0 disables shot noise
    read_noise: float = 10.0       # read noise, electrons RMS
    bits: int = 8                  # ADC bit depth: 8, 10, 12 or 16
    colour: bool = False           # RGB camera (H, W, 3) if True, else monochrome (H, W)

    def __post_init__(self) -> None:
        if self.bits not in (8, 10, 12, 16):
            raise InputError(f"ImagingModel: bits must be 8, 10, 12 or 16, found {self.bits}")
        for name in ("gain", "ref_distance", "ambient", "global_fraction", "global_blur", "gamma", "black_level",
                     "projector_blur", "camera_blur", "full_well", "read_noise"):
            value = getattr(self, name)
            if not np.isfinite(value) or value < 0:
                raise InputError(f"ImagingModel: {name} must be finite and >= 0, found {value}")
        if self.ref_distance == 0 or self.gamma == 0:
            raise InputError("ImagingModel: ref_distance and gamma must be > 0")

    @property
    def max_value(self) -> int:
        """Largest digital number the ADC outputs, ``2**bits - 1``."""
        return (1 << self.bits) - 1

    @property
    def dtype(self) -> type:
        return np.uint8 if self.bits == 8 else np.uint16

    def noiseless(self) -> "ImagingModel":
        """The same model without shot or read noise (quantisation stays)."""
        return ImagingModel(**{**asdict(self), "full_well": 0.0, "read_noise": 0.0})

    def noise_std(self, signal: np.ndarray) -> np.ndarray:
        """Standard deviation of the recorded signal, in full-scale fractions, for an expected ``signal``.

        ``sqrt(signal * full_well + read_noise^2) / full_well`` (shot + read). Quantisation adds a
        further ``1 / (12 * max_value^2)`` of variance, and clipping at 0 and 1 changes both.
        """
        s = np.asarray(signal, dtype=np.float64)
        if self.full_well == 0:
            return np.zeros_like(s)
        return np.sqrt(np.maximum(s, 0) * self.full_well + self.read_noise ** 2) / self.full_well

    def radiance(self, pattern: np.ndarray) -> np.ndarray:
        """Pattern image (uint8/uint16 full range, or float in [0, 1]) -> float32 projected radiance."""
        p = np.asarray(pattern)
        if p.dtype == np.uint8:
            lut = self.black_level + (1 - self.black_level) * (np.arange(256) / 255.0) ** self.gamma
            if p.size and (p.ndim == 2 or (p.ndim == 3 and p.shape[2] in (3, 4))):
                return cv2.LUT(np.ascontiguousarray(p), lut.astype(np.float32))   # the same lookup, faster
            return lut.astype(np.float32)[p]
        if p.dtype == np.uint16:
            values = p.astype(np.float32) / 65535.0
        elif np.issubdtype(p.dtype, np.floating):
            values = np.clip(p.astype(np.float32), 0.0, 1.0)
        else:
            raise PatternError(f"pattern image dtype {p.dtype} is not supported; use uint8, uint16 or float "
                               "in [0, 1]")
        return (self.black_level + (1 - self.black_level) * values ** np.float32(self.gamma)).astype(np.float32)


class ViewRenderer:
    """Renders camera images of one view (fixed geometry) for any projected pattern.

    Parameters
    ----------
    geometry : ViewGeometry from :func:`rangekit.sim.scene.raycast.cast_view`.
    model : ImagingModel.
    projector_size : (width, height) of the projector in pixels; patterns must have this size.
    """

    def __init__(self, geometry: ViewGeometry, model: ImagingModel, projector_size: tuple[int, int]):
        self.model = model
        self.projector_size = (int(projector_size[0]), int(projector_size[1]))
        self.shape = geometry.hit.shape
        H, W = self.shape
        Wp, Hp = self.projector_size
        g = geometry
        lit = g.lit.ravel()
        self._lit_idx = np.flatnonzero(lit)
        # Bilinear sampling at the exact projector coordinates, edge pixels replicated.
        x = np.clip(g.proj_col.ravel()[self._lit_idx], 0.0, Wp - 1.0)
        y = np.clip(g.proj_row.ravel()[self._lit_idx], 0.0, Hp - 1.0)
        x0 = np.minimum(np.floor(x), max(Wp - 2, 0)).astype(np.int64)
        y0 = np.minimum(np.floor(y), max(Hp - 2, 0)).astype(np.int64)
        fx = (x - x0).astype(np.float32)
        fy = (y - y0).astype(np.float32)
        self._i00 = y0 * Wp + x0
        self._dx = 1 if Wp > 1 else 0
        self._dy = Wp if Hp > 1 else 0
        self._w = ((1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy)
        # Per-pixel factors (channels last; mono averages the RGB albedo: a flat spectral response).
        albedo = g.albedo.reshape(-1, 3)
        falloff = (model.ref_distance / g.proj_dist.ravel()[self._lit_idx]) ** 2
        direct = (albedo[self._lit_idx] * g.cos_proj.ravel()[self._lit_idx, None]
                  + g.specular.ravel()[self._lit_idx, None]) * (model.gain * falloff)[:, None]
        if not model.colour:
            direct = direct.mean(axis=1, keepdims=True)
            albedo = albedo.mean(axis=1, keepdims=True)
        self._direct = direct.astype(np.float32)                          # (n_lit, C)
        self._ambient = (model.gain * model.ambient * albedo).astype(np.float32)  # (H*W, C)
        self._global = (model.gain * model.global_fraction * albedo).astype(np.float32)
        self._hit_mask = geometry.hit.astype(np.float32)

    @property
    def n_channels(self) -> int:
        return 3 if self.model.colour else 1

    def expected(self, pattern: np.ndarray) -> np.ndarray:
        """Noise-free camera signal in full-scale fractions (before clipping and quantisation).

        Returns (H, W) float32, or (H, W, 3) for a colour camera.
        """
        Wp, Hp = self.projector_size
        p = np.asarray(pattern)
        if p.shape[:2] != (Hp, Wp) or p.ndim not in (2, 3) or (p.ndim == 3 and p.shape[2] != 3):
            raise PatternError(f"pattern image has shape {p.shape}; the projector needs ({Hp}, {Wp}) or "
                               f"({Hp}, {Wp}, 3) (height, width[, RGB])")
        L = self.model.radiance(p)
        if self.model.projector_blur > 0:
            L = cv2.GaussianBlur(L, (0, 0), self.model.projector_blur, borderType=cv2.BORDER_CONSTANT)
        L = L.reshape(Hp * Wp, -1)  # (Hp*Wp, 1 or 3)
        mean_L = L.mean(axis=0)
        if L.shape[1] == 3 and not self.model.colour:
            L = L.mean(axis=1, keepdims=True)  # flat spectral response of a mono sensor
            mean_L = mean_L.mean(keepdims=True)
        w00, w10, w01, w11 = self._w
        C = self.n_channels
        H, W = self.shape
        local = self.model.global_fraction > 0 and self.model.global_blur > 0
        img = self._ambient + (0 if local else self._global * mean_L.astype(np.float32))
        if img.shape[1] != C:
            img = np.repeat(img, C, axis=1)
        if not local:   # img[lit] += direct * bilinear(L), in one compiled pass
            if L.shape[1] != C:   # a grey pattern on a colour camera
                L = np.repeat(L, C, axis=1)
            add_direct(img, np.ascontiguousarray(L, dtype=np.float32), self._i00, self._dx, self._dy,
                       w00, w10, w01, w11, self._direct, self._lit_idx)
        else:
            i = self._i00
            vals = (L[i] * w00[:, None] + L[i + self._dx] * w10[:, None]
                    + L[i + self._dy] * w01[:, None] + L[i + self._dy + self._dx] * w11[:, None])
            img[self._lit_idx] += self._direct * vals
            direct = np.zeros((H * W, C), np.float32)
            direct[self._lit_idx] = self._direct * vals
            img += self._local_global(direct.reshape(H, W, C)).reshape(H * W, C)
        img = img.reshape(H, W, C) if C == 3 else img.reshape(H, W)
        if self.model.camera_blur > 0:
            img = cv2.GaussianBlur(img, (0, 0), self.model.camera_blur, borderType=cv2.BORDER_REPLICATE)
        return img

    def _local_global(self, direct: np.ndarray) -> np.ndarray:
        """Global light at each surface pixel: global_fraction x the direct light around it.

        The direct image is averaged with a Gaussian of ``global_blur`` camera pixels over the surface
        (normalised by the blurred surface mask, so object borders are not darkened), computed at a
        quarter of the resolution (the kernel is wide).
        """
        H, W, C = direct.shape
        f = 4 if self.model.global_blur >= 8 else 1
        small = (max(W // f, 1), max(H // f, 1))
        sigma = self.model.global_blur / f
        d = cv2.resize(direct, small, interpolation=cv2.INTER_AREA).reshape(small[1], small[0], C)
        m = cv2.resize(self._hit_mask, small, interpolation=cv2.INTER_AREA)
        d = cv2.GaussianBlur(d, (0, 0), sigma).reshape(small[1], small[0], C)
        m = cv2.GaussianBlur(m, (0, 0), sigma)
        avg = d / np.maximum(m, 1e-6)[:, :, None]
        avg = cv2.resize(avg, (W, H), interpolation=cv2.INTER_LINEAR).reshape(H, W, C)
        return np.float32(self.model.global_fraction) * avg * self._hit_mask[:, :, None]

    def render(self, pattern: np.ndarray, rng: np.random.Generator, exposure: Exposure | None = None) -> np.ndarray:
        """One noisy, quantised capture: (H, W) or (H, W, 3), uint8 for 8 bits else uint16 (LSB-aligned).
        ``exposure``: the camera's exposure and ISO (:mod:`rangekit.sim.imaging.sensor`; default the reference)."""
        return digitise(self.expected(pattern), self.model, exposure or Exposure(), rng)

    def render_many(self, patterns: list[np.ndarray], rngs: list[np.random.Generator], *,
                    workers: int = 0, exposures: list[Exposure] | None = None) -> list[np.ndarray]:
        """Render several patterns on ``workers`` threads (numpy and OpenCV release the GIL; 0: the configured
        number, :func:`rangekit._runtime.executor.worker_count`)."""
        workers = worker_count(workers)
        if len(patterns) != len(rngs):
            raise InputError(f"render_many: {len(patterns)} patterns but {len(rngs)} generators")
        exposures = exposures if exposures is not None else [Exposure()] * len(patterns)
        if workers <= 1 or len(patterns) < 2:
            return [self.render(p, r, e) for p, r, e in zip(patterns, rngs, exposures)]
        with ThreadPoolExecutor(max_workers=workers) as pool:
            return list(pool.map(self.render, patterns, rngs, exposures))
