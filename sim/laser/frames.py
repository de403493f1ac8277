"""Laser-line frames of a posed scene: the laser-off (ambient) image and one image per line laser,
with exact ground truth.

Per view (turntable angle): one full camera ray cast (depth, the ambient image) and one ray-casting
scene. Per laser frame: the lit curve (:func:`rangekit.sim.laser.curve.lit_curve`) is drawn as a
Gaussian line, formed as a camera forms it: the irradiance across the sheet is a Gaussian of std
sigma = line width (1/e^2) / 4, projected through the surface into pixels; the lens PSF (a Gaussian of
std ``ImagingModel.camera_blur``) widens it optically, and each pixel integrates the light over its
square. So each curve sample is splatted as an isotropic Gaussian of std sqrt(sigma^2 + blur^2)
integrated over every pixel (normal-CDF differences at the pixel edges), with the energy
``power * gain * cos(incidence) * albedo * speckle * spacing * sqrt(2 pi) sigma`` (a line's peak before
the blur is ``power * gain * cos * albedo``, full-scale fractions). Sampling the profile at pixel
centres and blurring the sampled image afterwards, as this module did first, aliases the narrow lines
(sigma 0.3-0.6 px on foreshortened surfaces) and cost 0.02 px of peak error by itself. Speckle is
multiplicative along the line (log-normal, contrast ``speckle``, correlated over ``speckle_px`` pixels
along the curve); the line is added to the ambient image, and the sensor noise of
:class:`ImagingModel` (shot + read, :meth:`ImagingModel.noise_std`) and quantisation to its bits are
applied. A colour camera sees a red laser mostly in R (:data:`CHANNEL_RESPONSE`).

Ambient image: ``gain * ambient * albedo * (0.3 + 0.7 cos(normal, view))`` (room light and a headlight).

Noise: the standard normals come from a pool drawn once per seed and image size (1.03x the image), each
frame reading a window at a random offset: at every pixel the off frame and each laser frame get independent values
(drawing 3.7 M normals per RGB frame would cost 40 ms, the whole frame budget).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np
from scipy.special import erf

from rangekit.errors import SceneError
from rangekit.rig.rig_file import Rig
from rangekit.sim.laser.curve import LitCurve, lit_curve
from rangekit.sim.scene.raycast import cast_view
from rangekit.sim.imaging.render import ImagingModel
from rangekit.sim.scene.scene import Scene
from rangekit.surface.raycast import raycasting_scene

__all__ = ["LaserLook", "LaserFrame", "LaserView", "CHANNEL_RESPONSE"]

#: Response of an RGB camera's (R, G, B) channels to each laser colour (a mono camera: 1).
CHANNEL_RESPONSE = {"red": (1.0, 0.06, 0.02), "green": (0.05, 1.0, 0.08), "blue": (0.02, 0.08, 1.0),
                    "white": (1.0, 1.0, 1.0)}


@dataclass(frozen=True)
class LaserLook:
    """What a laser frame looks like beyond the ImagingModel: room light and speckle."""

    ambient: float = 0.12          # room light on a white surface facing the camera, full-scale fraction
    speckle: float = 0.15          # speckle contrast (std / mean of the multiplicative factor); 0: none
    speckle_px: float = 1.5        # speckle grain along the line, pixels
    max_spacing_px: float = 0.5    # curve samples at most this far apart in the image (px)
    max_sigma_px: float = 4.0      # the profile's sigma is capped here (grazing surfaces)


@dataclass(frozen=True, eq=False)
class LaserFrame:
    """One laser frame: ``image`` (H, W[, 3]) uint8/uint16; the per-pixel truth as ``pixels`` (M, 2) int64
    (row, col) of the pixels the lit curve passes through and ``points`` (M, 3) float64 the world point
    there (the curve sample projecting nearest the pixel centre); ``curve`` the dense visible samples
    (``curve.uv`` distorted pixels, ``curve.xyz`` world)."""

    image: np.ndarray
    pixels: np.ndarray
    points: np.ndarray
    curve: LitCurve

    @property
    def xyz(self) -> np.ndarray:
        """(H, W, 3) float64 dense truth: ``points`` at ``pixels``, NaN elsewhere."""
        H, W = self.image.shape[:2]
        out = np.full((H, W, 3), np.nan)
        out[self.pixels[:, 0], self.pixels[:, 1]] = self.points
        return out


_POOLS: dict[tuple[int, int], np.ndarray] = {}


def _pixel_fractions(x: np.ndarray, inv: np.ndarray) -> np.ndarray:
    """(N, K-1) float64: the fraction of a unit Gaussian between consecutive edges ``x`` (N, K) (pixel edges
    minus the centre, px), ``inv`` (N, 1) = 1 / (sqrt(2) std): half the differences of erf."""
    return 0.5 * np.diff(erf(x * inv), axis=1)


#: The ambient camera's pixel rays, which do not change between turntable steps: (camera, rays) by
#: (id(camera), width, height); the camera is held so that its id is not reused (at most two kept).
_RAYS: dict[tuple[int, int, int], tuple[object, tuple[np.ndarray, np.ndarray]]] = {}


def _pixel_rays(base, cam) -> tuple[np.ndarray, np.ndarray]:
    """:func:`rangekit.camera.world_pixel_rays` of ``cam`` (``base`` resized), cached per ``base`` object."""
    from rangekit.camera import world_pixel_rays

    key = (id(base), cam.width, cam.height)
    if key not in _RAYS or _RAYS[key][0] is not base:
        if len(_RAYS) >= 2:
            _RAYS.pop(next(iter(_RAYS)))
        _RAYS[key] = (base, world_pixel_rays(cam))
    return _RAYS[key][1]


def _noise_pool(seed: int, size: int) -> np.ndarray:
    """(size,) float32 standard normals for ``seed``, drawn once per process (read-only, shared by views)."""
    if (seed, size) not in _POOLS:
        if len(_POOLS) >= 2:
            _POOLS.pop(next(iter(_POOLS)))
        pool = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(size, 0))).standard_normal(
            size, dtype=np.float32)
        pool.flags.writeable = False
        _POOLS[(seed, size)] = pool
    return _POOLS[(seed, size)]


class LaserView:
    """The laser frames of ``scene`` on ``rig`` (which must have lasers) at turntable ``angle`` radians.

    ``imaging`` gives gain, blur, noise, bits and colour; ``seed`` the noise (the same seed, angle and
    laser give the same bytes). ``ambient_scale`` 1 casts every camera pixel once per view (the ambient
    image and the ``depth`` truth, ~1 s at 1280x960); k > 1 casts a camera k times smaller and upsamples
    the ambient image (k = 4: ~16x cheaper; ``depth`` is then None): for scans of many turntable steps.
    The laser lines and their truth are exact either way. ``cam_rays``, ``corner_rays``: cached rays for
    :func:`~rangekit.sim.scene.raycast.cast_view` of the camera cast (``camera.resized(W // k, H // k)`` when
    ``ambient_scale`` is k > 1); views of one camera share them: 0.9 s less per view at 1280x1024.
    """

    def __init__(self, scene: Scene, rig: Rig, angle: float = 0.0, *, imaging: ImagingModel | None = None,
                 look: LaserLook | None = None, seed: int = 0, ambient_scale: int = 1,
                 cam_rays: tuple[np.ndarray, np.ndarray] | None = None,
                 corner_rays: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        if not rig.lasers:
            raise SceneError("laser rendering: the rig has no lasers (rig file 'lasers'); use "
                             "rangekit.sim.laser.rig.laser_rig()")
        self.rig, self.camera = rig, rig.camera
        self.imaging = imaging if imaging is not None else ImagingModel()
        self.look = look if look is not None else LaserLook()
        self.angle = float(angle)
        motion = rig.T_world_rotated(angle) if rig.T_world_table is not None else None
        self.mesh = scene.world_mesh(motion)
        self.rc_scene = raycasting_scene(self.mesh.vertices, self.mesh.triangles)
        m = self.imaging
        H, W = self.shape = (self.camera.height, self.camera.width)
        self.ambient_scale = int(ambient_scale)
        if self.ambient_scale < 1:
            raise SceneError(f"LaserView: ambient_scale must be an integer >= 1, found {ambient_scale!r}")
        cam = self.camera if self.ambient_scale == 1 else self.camera.resized(
            max(W // self.ambient_scale, 1), max(H // self.ambient_scale, 1))
        self.geometry = g = cast_view(self.mesh, cam, None, corner_rays=corner_rays,
                                      cam_rays=cam_rays if cam_rays is not None else _pixel_rays(self.camera, cam))
        view = cam.center - np.nan_to_num(g.xyz)
        view /= np.maximum(np.linalg.norm(view, axis=2, keepdims=True), 1e-12)
        shade = np.where(g.hit, 0.3 + 0.7 * np.clip(np.einsum("ijk,ijk->ij", np.nan_to_num(g.normal), view), 0, 1), 0)
        albedo = g.albedo if m.colour else g.albedo.mean(axis=2, keepdims=True)
        amb = (m.gain * self.look.ambient * albedo * shade[:, :, None]).astype(np.float32)
        amb = amb if m.colour else amb[:, :, 0]
        if self.ambient_scale > 1:
            amb = cv2.resize(amb, (W, H), interpolation=cv2.INTER_LINEAR)
        if m.camera_blur > 0:
            amb = cv2.GaussianBlur(amb, (0, 0), m.camera_blur, borderType=cv2.BORDER_REPLICATE)
        self._ambient = amb
        self._ambient_std = m.noise_std(amb).astype(np.float32)
        key = int(round((self.angle % (2 * math.pi)) * 1e9))
        self._seed = (int(seed), key)
        self._pool = _noise_pool(int(seed), int(amb.size * 1.03) + 1)
        self._curves: dict[int, LitCurve] = {}

    # ---------------------------------------------------------------- truth
    @property
    def depth(self) -> np.ndarray | None:
        """(H, W) float64 camera z of the surface each pixel sees, metres; NaN where none (None unless
        ``ambient_scale`` is 1)."""
        return self.geometry.depth if self.ambient_scale == 1 else None

    def curve(self, k: int) -> LitCurve:
        """The visible lit curve of laser ``k`` (cached)."""
        if k not in self._curves:
            self._curves[k] = lit_curve(self.mesh, self.rc_scene, self.camera, self.rig.lasers[k],
                                        max_spacing_px=self.look.max_spacing_px)
        return self._curves[k]

    def truth_pixels(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """Laser ``k``'s per-pixel truth: ((M, 2) int64 (row, col) of every pixel its curve passes through,
        (M, 3) float64 world point there: the sample projecting nearest the pixel centre, within half a
        pixel of it)."""
        c = self.curve(k)
        W = self.shape[1]
        pix = np.rint(c.uv).astype(np.int64)
        idx = pix[:, 1] * W + pix[:, 0]
        r2 = np.sum((c.uv - pix) ** 2, axis=1)
        order = np.lexsort((r2, idx))
        first = order[np.r_[True, idx[order][1:] != idx[order][:-1]]] if order.size else order
        return pix[first][:, ::-1].copy(), c.xyz[first]

    def truth_xyz(self, k: int) -> np.ndarray:
        """(H, W, 3) float64 world point of laser ``k``'s curve at each pixel it passes through, NaN
        elsewhere (:meth:`truth_pixels` as a map)."""
        pixels, points = self.truth_pixels(k)
        out = np.full(self.shape + (3,), np.nan)
        out[pixels[:, 0], pixels[:, 1]] = points
        return out

    # ---------------------------------------------------------------- images
    def _rng(self, frame: int) -> np.random.Generator:
        return np.random.default_rng(np.random.SeedSequence(self._seed[0], spawn_key=(self._seed[1], frame + 1)))

    def _line(self, k: int, rng: np.random.Generator):
        """Laser ``k``'s line alone, blurred and pixel-integrated: ((H', W') float32 in full-scale
        fractions, (row0, col0)) or
        None when no sample is visible."""
        c, laser, look = self.curve(k), self.rig.lasers[k], self.look
        if len(c.uv) == 0:
            return None
        amp = laser.power * self.imaging.gain * c.peak
        if look.speckle > 0:
            # log-normal factor with mean 1, smoothed along the samples (they run along the curve)
            s2 = math.log1p(look.speckle ** 2)
            g = rng.standard_normal(len(amp))
            n = max(int(round(look.speckle_px / look.max_spacing_px)), 1)
            if n > 1:
                g = np.convolve(g, np.ones(n) / math.sqrt(n), mode="same")
            amp = amp * np.exp(math.sqrt(s2) * g - s2 / 2)
        # The line's irradiance is a Gaussian of std sigma across the sheet; the lens PSF (a Gaussian of
        # std camera_blur) widens it optically, before the sensor, and each pixel integrates the light over
        # its square: each sample is splatted as a Gaussian of std sqrt(sigma^2 + blur^2) integrated over
        # every pixel (differences of the normal CDF at the pixel edges). Sampling the narrow profile at
        # pixel centres and blurring the sampled image afterwards aliases lines of sigma < ~0.6 px.
        sigma = np.clip(c.sigma_px, 0.3, look.max_sigma_px)
        energy = amp * c.spacing_px * math.sqrt(2 * math.pi) * sigma   # peak amp for a line of this sigma
        s_tot = np.sqrt(sigma ** 2 + self.imaging.camera_blur ** 2)
        R = int(math.ceil(3.5 * s_tot.max()))
        H, W = self.shape
        u0, v0 = np.rint(c.uv[:, 0]).astype(np.int64), np.rint(c.uv[:, 1]).astype(np.int64)
        pad = R + 3
        c0, r0 = max(u0.min() - pad, 0), max(v0.min() - pad, 0)
        c1, r1 = min(u0.max() + pad + 1, W), min(v0.max() + pad + 1, H)
        w_roi, h_roi = c1 - c0, r1 - r0
        d = np.arange(-R, R + 1)
        edges = np.arange(-R - 0.5, R + 1.0)                            # (2R+2,) pixel edges about u0, v0
        inv = (1.0 / (math.sqrt(2.0) * s_tot))[:, None]
        cu = _pixel_fractions((u0 - c.uv[:, 0])[:, None] + edges, inv)       # (N, 2R+1) fraction in each column
        cv = _pixel_fractions((v0 - c.uv[:, 1])[:, None] + edges, inv) * energy[:, None]
        weights = (cv.astype(np.float32)[:, :, None] * cu.astype(np.float32)[:, None, :]).ravel()
        rows = np.clip(v0[:, None] + d - r0, 0, h_roi - 1)
        cols = np.clip(u0[:, None] + d - c0, 0, w_roi - 1)
        flat = (rows[:, :, None] * w_roi + cols[:, None, :]).ravel()
        img = np.bincount(flat, weights, minlength=h_roi * w_roi).astype(np.float32).reshape(h_roi, w_roi)
        return img, (r0, c0)

    def _finish(self, img: np.ndarray, rng: np.random.Generator, roi=None) -> np.ndarray:
        """Noise (standard normals from the pool at a random offset; the ambient image's std, recomputed
        inside ``roi`` = (slices) where the line adds light), clipping and quantisation."""
        m = self.imaging
        if m.full_well > 0:
            off = int(rng.integers(0, self._pool.size - img.size + 1))
            window = self._pool[off: off + img.size].reshape(img.shape)
            noise = self._ambient_std * window
            if roi is not None:
                noise[roi] = m.noise_std(img[roi]).astype(np.float32) * window[roi]
            img += noise
        img *= np.float32(m.max_value)
        np.clip(img, 0, m.max_value, out=img)
        img += np.float32(0.5)  # round half up by truncation
        return img.astype(m.dtype)

    def off(self) -> np.ndarray:
        """The laser-off image: ambient light only. (H, W[, 3]), the ImagingModel's dtype."""
        return self._finish(self._ambient.copy(), self._rng(-1))

    def frame(self, k: int) -> LaserFrame:
        """Laser ``k`` on (the others off): the image and the ground truth."""
        rng = self._rng(k)
        img, roi = self._ambient.copy(), None
        line = self._line(k, rng)
        if line is not None:
            L, (r0, c0) = line
            h, w = L.shape
            roi = (slice(r0, r0 + h), slice(c0, c0 + w))
            if self.imaging.colour:
                resp = np.asarray(CHANNEL_RESPONSE[self.rig.lasers[k].channel], np.float32)
                img[roi] += L[:, :, None] * resp
            else:
                img[roi] += L
        pixels, points = self.truth_pixels(k)
        return LaserFrame(image=self._finish(img, rng, roi), pixels=pixels, points=points, curve=self.curve(k))
