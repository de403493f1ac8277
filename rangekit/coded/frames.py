"""A capture stack as one (K, H, W) array with frames by name, and the row chunks decoders work on.

Colour captures become grey as the integer mean of R, G and B in the captures' own dtype (the rule of
:func:`rangekit.image.to_grey`, rounded down, so the stack never needs a float copy).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import numpy as np

from rangekit._runtime.executor import worker_count
from rangekit.errors import DecodeError
from rangekit.coded.patterns import PatternSpec

__all__ = ["CaptureStack", "row_chunks", "run_parallel"]


class CaptureStack:
    """The capture stack as one (K, H, W) array with frame indices by name (colour converted to grey)."""

    def __init__(self, stack, spec: PatternSpec, order: str) -> None:
        names = spec.frame_names_in(order)
        if isinstance(stack, np.ndarray):
            if stack.ndim not in (3, 4):
                raise DecodeError(f"the capture stack must be (K, H, W) or (K, H, W, 3), found shape {stack.shape}")
            frames = stack
        else:
            frames = [np.asarray(f) for f in stack]
        if len(frames) != len(names):
            raise DecodeError(f"found {len(frames)} captures, pattern {spec.method!r} on a {spec.width}x{spec.height} "
                              f"projector needs {len(names)} ({', '.join(names[:4])}{', ...' if len(names) > 4 else ''})")
        shape0, dtype0 = frames[0].shape, frames[0].dtype
        if not isinstance(frames, np.ndarray):
            for i, f in enumerate(frames):
                if f.shape != shape0:
                    raise DecodeError(f"capture {i} has shape {f.shape}, capture 0 has {shape0}; all captures must "
                                      "have the same size")
                if f.dtype != dtype0:
                    raise DecodeError(f"capture {i} is {f.dtype}, capture 0 is {dtype0}; mixed bit depths")
        if dtype0 not in (np.uint8, np.uint16):
            raise DecodeError(f"captures have dtype {dtype0}; expected uint8 or uint16 raw captures")
        if len(shape0) not in (2, 3) or (len(shape0) == 3 and shape0[2] != 3):
            raise DecodeError(f"captures must be (H, W) grey or (H, W, 3) RGB images, found {shape0}")
        self.colour = len(shape0) == 3
        self.colour_white = frames[names.index("white")] if "white" in names else None
        if self.colour:  # grey = mean of RGB, in the captures' own dtype
            frames = [(np.asarray(f).sum(axis=2, dtype=np.uint32) // 3).astype(dtype0) for f in frames]
        if isinstance(frames, np.ndarray):
            self.stack = np.ascontiguousarray(frames)
        else:
            self.stack = np.stack(frames)  # one copy; pass a (K, H, W) array to avoid it
        self.index = {n: i for i, n in enumerate(names)}
        self.shape = shape0[:2]
        self.dtype = dtype0

    def get(self, name: str, region: tuple[slice, slice]) -> np.ndarray:
        return self.stack[self.index[name]][region]


def row_chunks(n: int, size: int) -> list[slice]:
    """Slices of ``size`` rows covering ``range(n)``."""
    return [slice(i, min(i + size, n)) for i in range(0, n, size)]


def run_parallel(fn, items, workers: int) -> None:
    """Call ``fn`` on every item, on ``workers`` threads (in order on one; 0: the configured number,
    :func:`rangekit._runtime.executor.worker_count`)."""
    workers = worker_count(workers)
    if workers <= 1:
        for it in items:
            fn(it)
        return
    with ThreadPoolExecutor(max_workers=workers) as pool:
        for _ in pool.map(fn, items):
            pass
