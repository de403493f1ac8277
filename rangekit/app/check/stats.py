"""What ``rangekit check`` measures in the white and black captures, and how it shows it.

All values are fractions of the camera's full scale (``2**bits - 1``). The *object* is a boolean mask
(H, W): on the simulator the truth's lit object pixels; on hardware the pixels the projector visibly
lights (white - black above :data:`LIT_FRACTION` of full scale, or white at full scale).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from rangekit.colour import colourise

__all__ = ["LIT_FRACTION", "TARGET_P99", "DARK_TARGET", "ImageStats", "image_stats", "lit_mask", "check_figure"]

#: Hardware's object mask: white - black above 1% of full scale (or white saturated).
LIT_FRACTION = 0.01
#: The suggested exposure puts the 99th percentile of white on the object at 90% of full scale.
TARGET_P99 = 0.9
#: The exposure for the dark parts puts the 5th percentile of the contrast on the object at 10% of full scale.
DARK_TARGET = 0.1
_BINS = 20


@dataclass(frozen=True)
class ImageStats:
    """Statistics of one white/black pair over the object mask (fractions of full scale)."""

    n_object: int                         # object pixels
    saturated_fraction: float             # object pixels at full scale in any channel under white
    channel_saturation: dict              # channel name -> its fraction at full scale
    dark_fraction: float                  # object pixels with white - black below min_confidence
    white_p99: float                      # 99th percentile of white (brightest channel) on the object
    contrast_percentiles: dict            # "p1", "p5", "p50", "p95", "p99" of white - black on the object
    histogram: tuple                      # (counts (20,), edges (21,)) of white - black on the object


def _fraction(image: np.ndarray, full_scale: float) -> np.ndarray:
    return np.asarray(image, dtype=np.float32) / np.float32(full_scale)


def lit_mask(white: np.ndarray, black: np.ndarray, full_scale: float) -> np.ndarray:
    """(H, W) bool: the pixels the projector visibly lights (hardware's object mask)."""
    w, b = _fraction(white, full_scale), _fraction(black, full_scale)
    if w.ndim == 3:
        return ((w - b).mean(axis=2) > LIT_FRACTION) | (w >= 1.0).any(axis=2)
    return ((w - b) > LIT_FRACTION) | (w >= 1.0)


def image_stats(white: np.ndarray, black: np.ndarray, full_scale: float, mask: np.ndarray,
                min_confidence: float) -> ImageStats:
    """Saturation, dark fraction, white percentile and contrast histogram of (H, W[, 3]) captures."""
    w, b = _fraction(white, full_scale), _fraction(black, full_scale)
    m = np.asarray(mask, dtype=bool)
    n = int(m.sum())
    if w.ndim == 3:
        names, wc = ("red", "green", "blue"), w[m]            # (n, 3), RGB as rangekit reads images
        contrast = (w - b).mean(axis=2)[m]
        brightest = wc.max(axis=1)
    else:
        names, wc = ("grey",), w[m][:, None]
        contrast = (w - b)[m]
        brightest = wc[:, 0]
    sat = wc >= 1.0
    per = {name: float(sat[:, i].mean()) if n else 0.0 for i, name in enumerate(names)}
    pct = {f"p{q}": float(np.percentile(contrast, q)) if n else 0.0 for q in (1, 5, 50, 95, 99)}
    counts, edges = np.histogram(np.clip(contrast, 0, 1), bins=_BINS, range=(0.0, 1.0))
    return ImageStats(n, float(sat.any(axis=1).mean()) if n else 0.0, per,
                      float((contrast < min_confidence).mean()) if n else 0.0,
                      float(np.percentile(brightest, 99)) if n else 0.0, pct,
                      (counts.astype(int).tolist(), edges.tolist()))


def check_figure(white: np.ndarray, black: np.ndarray, full_scale: float, mask: np.ndarray,
                 min_confidence: float, stats: ImageStats) -> np.ndarray:
    """(H, 2W + 320, 3) uint8 RGB: the white capture with saturated pixels red and too-dark object pixels
    blue, the white - black contrast map (turbo, 0..1 of full scale), and the contrast histogram."""
    w, b = _fraction(white, full_scale), _fraction(black, full_scale)
    grey = w.mean(axis=2) if w.ndim == 3 else w
    contrast = (w - b).mean(axis=2) if w.ndim == 3 else w - b
    left = np.repeat((np.clip(grey, 0, 1) * 255).astype(np.uint8)[:, :, None], 3, axis=2)
    sat = (w >= 1.0).any(axis=2) if w.ndim == 3 else w >= 1.0
    left[sat & mask] = (255, 0, 0)
    left[(contrast < min_confidence) & mask & ~sat] = (0, 0, 255)
    middle = colourise(np.clip(contrast, 0, 1), 0.0, 1.0)
    if middle.shape[:2] != left.shape[:2] or middle.ndim != 3:
        middle = np.zeros_like(left)
    middle = np.ascontiguousarray(middle[:, :, :3]).astype(np.uint8)
    H = left.shape[0]
    hist = np.full((H, 320, 3), 255, np.uint8)
    counts = np.asarray(stats.histogram[0], dtype=np.float64)
    top = max(counts.max(), 1.0)
    bar_w = 300 // len(counts)
    for i, c in enumerate(counts):
        h = int((H - 40) * c / top)
        cv2.rectangle(hist, (10 + i * bar_w, H - 20 - h), (10 + (i + 1) * bar_w - 2, H - 20), (80, 80, 80), -1)
    cv2.putText(hist, "white - black, 0..1 of full scale", (10, 15), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1)
    return np.concatenate([left, middle, hist], axis=1)
