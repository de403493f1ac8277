"""Multi-exposure (HDR) coded light: each exposure decoded on its own, merged per pixel.

Rule: each pixel takes the decode of the **longest exposure whose white frame is not saturated there**
(no channel at full scale) and which decoded; if none of its unsaturated exposures decoded, the longest
unsaturated one (undecoded); if every exposure is saturated, the shortest. Why this and not a radiance
merge: white is the brightest pattern, so an unsaturated white means every pattern frame of that exposure
is unsaturated at that pixel, and then the longest such exposure has the most signal above the read noise
(the best stripe edges); decoding is a per-exposure comparison of frames, which a radiance merge would
only approximate after undoing the camera's response and mixing exposures' noise. Falling back to a
shorter unsaturated exposure where the longest one did not decode recovers the pixels whose code failed
at one exposure for noise; both are unsaturated, so both are trustworthy.

The merged ``white`` is the chosen exposure's white scaled to the shortest exposure (a radiance image
that does not saturate where the shortest exposure does not).
"""

from __future__ import annotations

from dataclasses import fields, replace

import numpy as np

from rangekit.coded.result import DecodeResult
from rangekit.errors import InputError

__all__ = ["choose_exposure", "merge_decodes"]


def _saturated(white: np.ndarray, full_scale: float) -> np.ndarray:
    w = np.asarray(white)
    return (w >= full_scale).any(axis=2) if w.ndim == 3 else w >= full_scale


def choose_exposure(whites, valid, full_scale: float) -> np.ndarray:
    """(H, W) int index into the exposures (increasing) by the module's rule; ``whites`` the white frames,
    ``valid`` the (H, W) bool decoded maps, one per exposure."""
    unsat = np.stack([~_saturated(w, full_scale) for w in whites])          # (E, H, W)
    ok = np.stack(valid) & unsat
    E = len(whites)
    order = np.arange(E)[:, None, None]
    best_ok = np.where(ok, order, -1).max(axis=0)
    best_unsat = np.where(unsat, order, -1).max(axis=0)
    return np.where(best_ok >= 0, best_ok, np.maximum(best_unsat, 0)).astype(np.intp)


def merge_decodes(results: list[DecodeResult], exposures_us, full_scale: float) -> tuple[DecodeResult, np.ndarray]:
    """Merge the decodes of one view at increasing ``exposures_us``; returns the merged result and the
    (H, W) index of the exposure each pixel took. Each result must carry its ``white`` capture."""
    exps = [float(e) for e in exposures_us]
    if len(results) != len(exps) or not results or exps != sorted(exps) or any(r.white is None for r in results):
        raise InputError(f"merge_decodes: expected one decode with its white frame per increasing exposure, found "
                         f"{len(results)} decodes for exposures {exps}")
    idx = choose_exposure([r.white for r in results], [r.valid for r in results], full_scale)
    out = {}
    for f in fields(DecodeResult):
        maps = [getattr(r, f.name) for r in results]
        if any(m is None for m in maps):
            out[f.name] = None
            continue
        if f.name in ("moved_frames", "motion_unchecked"):   # the frames any exposure found moved; axes unchecked
            out[f.name] = tuple(dict.fromkeys(name for m in maps for name in m))
            continue
        if f.name == "white":
            maps = [np.asarray(m, dtype=np.float32) * np.float32(exps[0] / e) for m, e in zip(maps, exps)]
        stack = np.stack(maps)
        pick = idx.reshape((1, *idx.shape) + (1,) * (stack.ndim - 1 - idx.ndim))
        pick = np.broadcast_to(pick, (1, *stack.shape[1:]))
        out[f.name] = np.take_along_axis(stack, pick, axis=0)[0]
    dtype = np.asarray(results[0].white).dtype
    out["white"] = np.rint(out["white"]).astype(dtype) if np.issubdtype(dtype, np.integer) else out["white"]
    return replace(results[0], **out), idx
