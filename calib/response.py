"""Measure the projector's response (gamma) by projecting uniform grey levels.

Point the projector at a matte surface the camera sees (a wall, a white board, the scan target), then::

    fit = measure_response(rig.projector, rig.camera)
    # store fit.response in the rig file: "projector_response": {"gamma": 2.21}

The model and the fit are in :mod:`rangekit.coded.response`; the result does not depend on the surface's
albedo, the room light or the projector's black level. Keep the camera's exposure fixed and below
clipping on the full-white image.
"""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from rangekit.rig.devices import Camera, Projector
from rangekit.errors import InputError
from rangekit.progress import call_progress
from rangekit.coded.response import ResponseFit, fit_response

__all__ = ["measure_response", "DEFAULT_LEVELS"]

#: 17 levels from 0 to 1 in steps of 1/16 (uint8 values 0, 16, 32, ..., 239, 255 after rounding).
DEFAULT_LEVELS = tuple(np.linspace(0.0, 1.0, 17))


def measure_response(projector: Projector, camera: Camera, *, levels: Sequence[float] | None = None,
                     mask: np.ndarray | None = None, progress: Callable | None = None, **fit_options) -> ResponseFit:
    """Show each grey level on ``projector``, capture it with ``camera``, and fit the response.

    Parameters
    ----------
    projector : rangekit.rig.devices.Projector
        Shows (height, width) uint8 images of its ``resolution``.
    camera : rangekit.rig.devices.Camera
    levels : (K,) sequence of float in [0, 1], optional
        Pattern values to show; must include 0 and 1. Default :data:`DEFAULT_LEVELS` (17 levels). Each
        is shown as the uint8 value ``round(255 * level)`` and fitted at that quantised value.
    mask : (H, W) bool ndarray, optional
        Camera pixels to use (e.g. the white board); default every pixel with enough contrast.
    progress : ``progress(msg, done=None, total=None)``, optional (see :mod:`rangekit.progress`).
    fit_options : passed to :func:`rangekit.coded.response.fit_response` (``min_contrast``, ``full_scale``).

    Returns
    -------
    ResponseFit
        ``response`` goes into the rig file's ``projector_response``.

    Raises
    ------
    InputError
        Bad levels, or too few camera pixels see the projector with enough contrast.
    DeviceError
        From the devices.
    """
    lv = np.asarray(DEFAULT_LEVELS if levels is None else levels, dtype=np.float64).ravel()
    if lv.size == 0 or not np.all(np.isfinite(lv)) or lv.min() < 0 or lv.max() > 1:
        raise InputError(f"measure_response: levels must be pattern values in [0, 1] including 0 and 1, found "
                         f"{lv.tolist()}")
    q = np.rint(lv * 255).astype(np.uint8)
    if np.unique(q).size != q.size:
        raise InputError(f"measure_response: levels {lv.tolist()} repeat after rounding to 8-bit values "
                         f"{q.tolist()}; give distinct levels at least 1/255 apart")
    W, H = projector.resolution
    images = []
    for k, value in enumerate(q):
        projector.show(np.full((H, W), value, np.uint8))
        images.append(camera.capture())
        call_progress(progress, f"grey level {value}/255", k + 1, len(q))
    return fit_response(q / 255.0, images, mask=mask, **fit_options)
