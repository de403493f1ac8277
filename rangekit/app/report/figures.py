"""The report's figures as HTML: an image embedded in a ``data:`` URI with its caption, thumbnails and crops.

Shared by every report section (:mod:`rangekit.app.report.page`, :mod:`rangekit.app.report.quality`,
:mod:`rangekit.app.laser.report`).
"""

from __future__ import annotations

import html

import numpy as np

__all__ = ["THUMB_W", "figure", "thumb", "crop"]

#: Width of a view's thumbnails, pixels.
THUMB_W = 256


def figure(image: np.ndarray | str, caption: str, alt: str | None = None) -> str:
    """``<figure>`` HTML of ``image`` ((H, W, 3) uint8 RGB, embedded as PNG, or a ``data:`` URI string)
    captioned ``caption`` (escaped); ``alt`` defaults to the caption."""
    from rangekit.rendering.snapshot import data_uri

    src = image if isinstance(image, str) else data_uri(image)
    cap = html.escape(caption)
    return f'<figure><img src="{src}" alt="{html.escape(alt or caption)}"><figcaption>{cap}</figcaption></figure>'


def thumb(image: np.ndarray, width: int = THUMB_W) -> np.ndarray:
    """``image`` resized to ``width`` pixels wide (aspect kept, area interpolation)."""
    import cv2

    h, w = image.shape[:2]
    return cv2.resize(image, (width, max(1, round(h * width / w))), interpolation=cv2.INTER_AREA)


def crop(image: np.ndarray, pad: int = 6) -> np.ndarray:
    """``image`` cut to its non-white content plus ``pad`` pixels (renders frame a bounding sphere)."""
    ys, xs = np.nonzero(np.any(image < 250, axis=2))
    if ys.size == 0:
        return image
    return image[max(0, ys.min() - pad):ys.max() + pad + 1, max(0, xs.min() - pad):xs.max() + pad + 1]
