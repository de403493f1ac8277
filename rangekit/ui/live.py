"""The Live page's picture: the camera's frame with a saturation and too-dark overlay, and a focus measure.

Colours as ``rangekit check`` draws them: red where a pixel is at full scale in any channel (saturated, its
value lost), blue where it is below :data:`DARK_FRACTION` of full scale (too dark to decode). The focus measure
is the variance of the Laplacian of the grey image, in (fractions of full scale)^2 x 1e4: larger is sharper;
it only compares frames of one scene (turn the focus ring to its maximum).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from rangekit.image import to_grey

__all__ = ["DARK_FRACTION", "LiveFrame", "focus_measure", "live_frame"]

#: A pixel below this fraction of full scale is marked too dark.
DARK_FRACTION = 0.02
#: JPEG quality of the streamed frames (the overlay stays legible, 1280x1024 in about 10 ms).
JPEG_QUALITY = 80

_RED = np.array([255, 0, 0], np.uint8)
_BLUE = np.array([40, 90, 255], np.uint8)


@dataclass(frozen=True)
class LiveFrame:
    """One streamed frame: ``jpeg`` (RGB with the overlay), its size in pixels and the figures shown beside it."""

    seq: int                    # the frame's number since the stream started
    jpeg: bytes
    width: int
    height: int
    saturated_fraction: float   # of all pixels, at full scale in any channel
    dark_fraction: float        # of all pixels, below DARK_FRACTION of full scale
    focus: float                # focus_measure of the frame
    extra: dict = field(default_factory=dict)   # what a job adds (the Calibrate page's board corners), JSON

    def figures(self) -> dict:
        """The figures as the page shows them (JSON)."""
        return {"seq": self.seq, "width": self.width, "height": self.height,
                "saturated_percent": round(100 * self.saturated_fraction, 2),
                "dark_percent": round(100 * self.dark_fraction, 2), "focus": round(self.focus, 2), **self.extra}


def focus_measure(image: np.ndarray, full_scale: float) -> float:
    """Variance of the Laplacian of ``image`` ((H, W) or (H, W, 3), values up to ``full_scale``) in fractions
    of full scale, times 1e4."""
    img = np.asarray(image)
    grey = to_grey(img).astype(np.float32) if img.ndim == 3 else img
    _, sd = cv2.meanStdDev(cv2.Laplacian(grey, cv2.CV_32F, ksize=3))
    return float((sd[0, 0] / float(full_scale)) ** 2 * 1e4)


def _overlay_lut(full_scale: float) -> np.ndarray:
    """(256, 1, 3) uint8: the overlay colour of each 8-bit grey value (red at full scale, blue-tinted below
    :data:`DARK_FRACTION`, grey otherwise)."""
    v = np.arange(256, dtype=np.uint16)
    rgb = np.repeat(v[:, None], 3, axis=1)
    dark = v < DARK_FRACTION * full_scale
    rgb[dark] = rgb[dark] // 2 + _BLUE // 2
    rgb[v >= full_scale] = _RED
    return rgb.astype(np.uint8)[:, None, :]


def live_frame(image: np.ndarray, full_scale: float, seq: int) -> LiveFrame:
    """The :class:`LiveFrame` of a camera frame ``image`` ((H, W) grey or (H, W, 3) RGB, uint8 or uint16,
    ``full_scale`` its largest value). An 8-bit grey frame is coloured through one look-up table (a few
    milliseconds at 1280x1024); other frames pixel class by pixel class."""
    img = np.asarray(image)
    if img.ndim == 2 and img.dtype == np.uint8:
        rgb8 = cv2.LUT(cv2.cvtColor(img, cv2.COLOR_GRAY2RGB), _overlay_lut(full_scale))
        n_sat = cv2.countNonZero((img >= full_scale).view(np.uint8)) if full_scale <= 255 else 0
        n_dark = cv2.countNonZero((img < DARK_FRACTION * full_scale).view(np.uint8))
    else:
        saturated = img >= full_scale
        if img.ndim == 3:
            saturated = saturated.any(axis=2)
        grey = to_grey(img) if img.ndim == 3 else img
        dark = grey < DARK_FRACTION * full_scale
        rgb8 = cv2.convertScaleAbs(img, alpha=255.0 / float(full_scale))
        rgb8 = cv2.cvtColor(rgb8, cv2.COLOR_GRAY2RGB) if rgb8.ndim == 2 else rgb8
        rgb8[dark] = rgb8[dark] // 2 + _BLUE // 2
        rgb8[saturated] = _RED
        n_sat, n_dark = int(saturated.sum()), int(dark.sum())
    ok, buf = cv2.imencode(".jpg", cv2.cvtColor(rgb8, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    if not ok:
        raise ValueError("live frame: OpenCV could not encode the JPEG")
    n = img.shape[0] * img.shape[1]
    return LiveFrame(seq, buf.tobytes(), img.shape[1], img.shape[0], n_sat / n, n_dark / n,
                     focus_measure(img, full_scale))
