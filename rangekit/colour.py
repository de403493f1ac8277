"""Colour maps: values to RGB uint8 through OpenCV's Turbo and Viridis tables, or grey.

One helper for every false-colour image (reports, snapshots, simulator previews, depth PNGs), so all of
them use the same tables: OpenCV's 256-entry ``COLORMAP_TURBO`` (Google's Turbo) and ``COLORMAP_VIRIDIS``
(matplotlib's viridis), converted from BGR to RGB.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from rangekit.errors import InputError

__all__ = ["COLOUR_MAPS", "colour_table", "colourise"]

COLOUR_MAPS = ("turbo", "viridis", "grey")


@lru_cache(maxsize=None)
def colour_table(cmap: str) -> np.ndarray:
    """(256, 3) uint8 RGB table of ``cmap`` ("turbo", "viridis" or "grey"), read-only: entry k is the
    colour of the value k / 255 of the way from vmin to vmax."""
    if cmap not in COLOUR_MAPS:
        raise InputError(f"colourise: cmap must be one of {', '.join(COLOUR_MAPS)}, found {cmap!r}")
    ramp = np.arange(256, dtype=np.uint8)
    if cmap == "grey":
        table = np.repeat(ramp[:, None], 3, axis=1)
    else:
        import cv2

        code = cv2.COLORMAP_TURBO if cmap == "turbo" else cv2.COLORMAP_VIRIDIS
        table = cv2.applyColorMap(ramp.reshape(-1, 1), code)[:, 0, ::-1].copy()  # BGR -> RGB
    table.flags.writeable = False
    return table


def colourise(values: np.ndarray, vmin: float, vmax: float, *, cmap: str = "turbo",
              nan_colour=(255, 255, 255)) -> np.ndarray:
    """Map ``values`` to RGB: vmin -> the first entry of ``cmap``'s table, vmax -> the last (clipped outside).

    Parameters
    ----------
    values : any shape, float. Non-finite entries get ``nan_colour``.
    vmin, vmax : finite, ``vmin <= vmax``, in the values' units. With ``vmin == vmax`` values above
        it get the last colour and the others the first.
    cmap : "turbo", "viridis" or "grey" (:data:`COLOUR_MAPS`, :func:`colour_table`).
    nan_colour : RGB triple in [0, 255].

    Returns
    -------
    ``values.shape + (3,)`` uint8 RGB (the nearest of the table's 256 entries).
    """
    table = colour_table(cmap)
    if not (np.isfinite(vmin) and np.isfinite(vmax) and vmax >= vmin):
        raise InputError(f"colourise: expected finite vmin <= vmax, found vmin={vmin}, vmax={vmax}")
    nan = np.asarray(nan_colour, dtype=np.float64).reshape(-1)
    if nan.shape != (3,) or not np.all((nan >= 0) & (nan <= 255)):
        raise InputError(f"colourise nan_colour: expected an RGB triple in [0, 255], found {nan_colour!r}")
    # One compiled pass (rangekit._compiled.colour): the same float64 operations and bytes as
    # t = clip((v - vmin) / span, 0, 1); table[rint(255 t)] (the report colourises 1.3 Mpx maps).
    from rangekit._compiled.colour import colour_indices

    v = np.asarray(values)
    if v.dtype != np.float32 and v.dtype != np.float64:
        v = v.astype(np.float64)
    flat = np.ascontiguousarray(v).reshape(-1)
    out = np.empty((flat.size, 3), dtype=np.uint8)
    colour_indices(flat, float(vmin), float(vmax - vmin), _with_nan(table, nan.astype(np.uint8)), out)
    return out.reshape(v.shape + (3,))


def _with_nan(table: np.ndarray, nan: np.ndarray) -> np.ndarray:
    """(257, 3) uint8: ``table`` and, as entry 256, the NaN colour ``nan`` (3,) uint8."""
    return np.concatenate([table, nan[None]], axis=0)
