"""Projector pattern sets, each described by a serialisable :class:`PatternSpec`.

A spec names the method and the projector size; its frames are generated on demand (uint8 images of
the projector's size), so a 44-frame sequence never sits in memory twice. The spec is saved with every
capture (``patterns.json``) and checked when decoding.

Methods
-------
``white``: one full-white frame. ``black``: one black frame.
``graycode``: white, black, then for each coded axis ("columns", then "rows") one frame per bit, most
significant bit first, each followed by its inverse. ``n_bits = ceil(log2(width))`` for columns; a
1280x800 projector gives 2 + 2 * (11 + 10) = 44 frames. Column u is lit in bit frame b when bit b of
``gray(u)`` is 1, with ``gray(x) = x ^ (x >> 1)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterator

import numpy as np

from rangekit.errors import PatternError

__all__ = ["PatternSpec", "PATTERN_METHODS", "make_pattern_spec", "gray_encode", "gray_decode", "n_bits_for"]

PATTERN_METHODS = ("white", "black", "graycode")
_AXES = ("columns", "rows")


def gray_encode(x: np.ndarray) -> np.ndarray:
    """Binary-reflected Gray code of non-negative integers."""
    x = np.asarray(x, dtype=np.int64)
    return x ^ (x >> 1)


def gray_decode(g: np.ndarray) -> np.ndarray:
    """Inverse of :func:`gray_encode` (prefix XOR), vectorised."""
    g = np.asarray(g, dtype=np.int64)
    x = g.copy()
    shift = 1
    while shift < 63:
        x ^= x >> shift
        shift <<= 1
    return x


def n_bits_for(n: int) -> int:
    """Bits needed to give ``n`` stripes distinct codes: ceil(log2(n)), at least 1."""
    return max(1, int(np.ceil(np.log2(max(n, 2)))))


@dataclass(frozen=True)
class PatternSpec:
    """What was projected: method, projector size and options. JSON round trip with to_dict/from_dict."""

    method: str
    width: int                      # projector width in pixels
    height: int                     # projector height in pixels
    axes: tuple[str, ...] = ("columns", "rows")  # coded axes, for coded methods
    options: dict = field(default_factory=dict, hash=False)

    def __post_init__(self) -> None:
        if self.method not in PATTERN_METHODS:
            raise PatternError(f"unknown pattern method {self.method!r}; known: {', '.join(PATTERN_METHODS)}")
        if int(self.width) < 1 or int(self.height) < 1:
            raise PatternError(f"pattern size must be positive, found {self.width}x{self.height}")
        bad = [a for a in self.axes if a not in _AXES]
        if bad or not self.axes:
            raise PatternError(f"pattern axes must be a non-empty subset of {_AXES}, found {self.axes}")
        object.__setattr__(self, "axes", tuple(self.axes))

    # -------------------------------------------------------------- frame list
    def bits(self, axis: str) -> int:
        """Number of Gray-code bits for an axis."""
        return n_bits_for(self.width if axis == "columns" else self.height)

    @property
    def frame_names(self) -> list[str]:
        """One name per frame, in projection order, e.g. ``['white', 'black', 'col_b10', 'col_b10_inv', ...]``."""
        if self.method in ("white", "black"):
            return [self.method]
        names = ["white", "black"]
        for axis in self.axes:
            prefix = "col" if axis == "columns" else "row"
            for b in range(self.bits(axis) - 1, -1, -1):
                names += [f"{prefix}_b{b}", f"{prefix}_b{b}_inv"]
        return names

    @property
    def n_frames(self) -> int:
        return len(self.frame_names)

    def frame(self, index: int) -> np.ndarray:
        """Frame ``index`` as an (height, width) uint8 image (0 or 255 for binary patterns)."""
        names = self.frame_names
        if not 0 <= index < len(names):
            raise PatternError(f"pattern {self.method!r} has {len(names)} frames; frame {index} does not exist")
        name = names[index]
        H, W = self.height, self.width
        if name == "white":
            return np.full((H, W), 255, np.uint8)
        if name == "black":
            return np.zeros((H, W), np.uint8)
        prefix, bit = name.split("_")[:2]
        b = int(bit[1:])
        inverse = name.endswith("_inv")
        n = W if prefix == "col" else H
        stripe = ((gray_encode(np.arange(n)) >> b) & 1).astype(bool) ^ inverse
        line = np.where(stripe, 255, 0).astype(np.uint8)
        return np.broadcast_to(line[None, :] if prefix == "col" else line[:, None], (H, W)).copy()

    def frames(self) -> Iterator[np.ndarray]:
        for i in range(self.n_frames):
            yield self.frame(i)

    # -------------------------------------------------------------- serialisation
    def to_dict(self) -> dict:
        return {"method": self.method, "width": self.width, "height": self.height, "axes": list(self.axes),
                "options": dict(self.options), "frames": self.frame_names}

    @classmethod
    def from_dict(cls, data: dict, *, where: str = "pattern spec") -> "PatternSpec":
        try:
            spec = cls(method=data["method"], width=int(data["width"]), height=int(data["height"]),
                       axes=tuple(data.get("axes", _AXES)), options=dict(data.get("options", {})))
        except (KeyError, TypeError, ValueError) as exc:
            raise PatternError(f"{where}: expected method, width, height (and axes, options): {exc}") from exc
        if "frames" in data and list(data["frames"]) != spec.frame_names:
            raise PatternError(f"{where}: its frame list ({len(data['frames'])} frames) does not match what "
                               f"method {spec.method!r} generates ({spec.n_frames} frames)")
        return spec


def make_pattern_spec(method: str, projector_size: tuple[int, int], **options) -> PatternSpec:
    """A spec for ``method`` on a projector of ``(width, height)`` pixels."""
    axes = options.pop("axes", _AXES)
    return PatternSpec(method=method, width=int(projector_size[0]), height=int(projector_size[1]),
                       axes=tuple(axes), options=options)
