"""Projector pattern sets, each described by a serialisable :class:`PatternSpec`.

A spec names the method, the projector size and the options; its frames are generated on demand as
uint8 images of the projector's size ((H, W), or (H, W, 3) for colour), so a long sequence is never held
twice. The spec is saved with every capture (``patterns.json``) and checked when decoding.

Methods and frame lists (Fusiello ch. 13.2; pixel centres at integers, column u lit means value 255):

``white``, ``black``
    One frame.
``graycode``
    white, black, then for each coded axis ("columns" first, then "rows") one frame per bit, most
    significant first, each followed by its inverse. ``n_bits = ceil(log2(size))``: a 1280x800
    projector gives 2 + 2 * (11 + 10) = 44 frames. Column u is lit in frame ``col_b{b}`` when bit b
    of ``gray(u)`` is 1, ``gray(x) = x ^ (x >> 1)``; this is also OpenCV's ``GrayCodePattern``.
``xor02``, ``xor04`` (Gupta & Nayar, CVPR 2011)
    As graycode, but every bit frame coarser than the base is XORed with the base frame, bit 0 (stripes
    2 px wide) for XOR-02 and bit 1 (4 px) for XOR-04. Every frame then has only fine stripes, so
    long-range global light is about the same in a frame and its inverse.
``phase``
    white, black, then for each axis and each period T in ``periods`` (coarse to fine), ``steps``
    frames ``0.5 + 0.5 cos(2 pi u / T - 2 pi s / steps)``. The coarsest period is at least the axis
    size, so its phase is absolute; each finer phase is unwrapped with the coarser one. One period gives
    single-period phase shifting (its steps are ``fine_steps``). Values are rounded to nearest; option
    ``rounding: "down"`` makes them as SLStudio's ``computePhaseVector`` does (float32, truncated), so
    SLStudio's 2x3, N-step and single-period codecs are this method frame for frame.
``hybrid``
    The graycode frames, then ``steps`` phase frames of one ``period`` per axis: the Gray code gives the
    period, the phase the position inside it. Option ``min_bit`` m (default 0) leaves the Gray bits below m out
    (2 m frames fewer per axis): the code then names a block of ``2**m`` columns, whose centre unwraps the phase
    as long as ``2**m <= period / 2`` (a pixel read into the neighbouring block at a block edge is then still
    within half a period); the direct/global separation needs Gray bits 1 and 2, so m over 1 drops it.
``micro``, ``modulated``, ``ftp``, ``psp``, ``faps``
    Other tools' fringe codecs (SLStudio's micro and modulated phase shifting, OpenCV's sinusoidal
    patterns), their frames value for value as the tool makes them: :mod:`rangekit.coded.codecs.fringes`.
``debruijn`` (single shot, Fusiello 13.2.5)
    One RGB frame of vertical stripes ``stripe_width`` px wide. Stripe colours follow a de Bruijn
    sequence B(k, n) of transitions: colour_i = (colour_{i-1} + 1 + s_i) mod (k + 1), from a palette of
    k + 1 colours, so neighbours always differ and any n + 1 consecutive stripes identify their place.

Capture order: ``frame_names`` is rangekit's order. ``frame_names_in(order="opencv")`` gives OpenCV's
GrayCodePattern order for graycode (column pairs MSB first, row pairs, then white, then black).
"""

from __future__ import annotations

import math

from dataclasses import dataclass, field
from functools import lru_cache
from typing import Iterator

import numpy as np

from rangekit.budget import MAX_IMAGE_SIDE_PX, check_budget
from rangekit.coded.codecs.fringes import (FRINGE_METHODS, check_fringe_options, fringe_frame, fringe_frame_names,
                                           slstudio_phase_line, slstudio_shift)
from rangekit.coded.codecs.option_checks import is_number, show, whole_number
from rangekit.errors import PatternError

__all__ = ["PatternSpec", "PATTERN_METHODS", "MAX_PHASE_STEPS", "MAX_PHASE_LEVELS", "MAX_DEBRUIJN_LENGTH",
           "make_pattern_spec", "gray_encode", "gray_decode", "n_bits_for",
           "de_bruijn", "DEBRUIJN_PALETTE", "debruijn_stripe_colours"]

PATTERN_METHODS = ("white", "black", "graycode", "xor02", "xor04", "phase", "hybrid", "debruijn") + FRINGE_METHODS
_BINARY = ("graycode", "xor02", "xor04", "hybrid")
_AXES = ("columns", "rows")
_ORDERS = ("rangekit", "opencv")
_ROUNDINGS = ("nearest", "down")

# Linear RGB stripe colours (0/1 per channel), as distinct as a colour camera sees them.
DEBRUIJN_PALETTE = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1], [1, 1, 0], [1, 0, 1], [0, 1, 1], [1, 1, 1]],
                            dtype=np.uint8)

#: Limits of a spec (checked before any frame exists): phase steps per level, phase levels per axis, and the
#: length k**n of a de Bruijn sequence (generated in full). Sizes: 1..rangekit.budget.MAX_IMAGE_SIDE_PX.
MAX_PHASE_STEPS = 64
MAX_PHASE_LEVELS = 16
MAX_DEBRUIJN_LENGTH = 2**20

_DEFAULT_OPTIONS = {
    "phase": {"steps": 4, "periods": None, "fine_steps": 8},
    "hybrid": {"steps": 8, "period": 16},
    "debruijn": {"k": 6, "n": 3, "stripe_width": 8},
}


def gray_encode(x: np.ndarray) -> np.ndarray:
    """Binary-reflected Gray code of non-negative integers."""
    x = np.asarray(x, dtype=np.int64)
    return x ^ (x >> 1)


def gray_decode(g: np.ndarray) -> np.ndarray:
    """Inverse of :func:`gray_encode` (prefix XOR), vectorised."""
    x = np.asarray(g, dtype=np.int64).copy()
    shift = 1
    while shift < 63:
        x ^= x >> shift
        shift <<= 1
    return x


def n_bits_for(n: int) -> int:
    """Bits needed to give ``n`` stripes distinct codes: ceil(log2(n)), at least 1."""
    return max(1, int(np.ceil(np.log2(max(n, 2)))))


@lru_cache(maxsize=32)
def de_bruijn(k: int, n: int) -> tuple[int, ...]:
    """The lexicographically least de Bruijn sequence B(k, n): length k**n, every n-window once (cyclic)."""
    if k < 2 or n < 1:
        raise PatternError(f"de Bruijn B(k, n) needs k >= 2 and n >= 1, found k={k}, n={n}")
    a = [0] * k * n
    seq: list[int] = []

    def db(t: int, p: int) -> None:  # Ruskey, Savage & Wang's recursive algorithm (depth n)
        if t > n:
            if n % p == 0:
                seq.extend(a[1: p + 1])
        else:
            a[t] = a[t - p]
            db(t + 1, p)
            for j in range(a[t - p] + 1, k):
                a[t] = j
                db(t + 1, t)

    db(1, 1)
    return tuple(seq)


def debruijn_stripe_colours(k: int, n: int, n_stripes: int) -> np.ndarray:
    """Palette index of each stripe, (n_stripes,) int: transitions follow B(k, n) (see module doc)."""
    seq = np.array(de_bruijn(k, n), dtype=np.int64)
    if n_stripes - 1 > len(seq):
        raise PatternError(f"de Bruijn B({k}, {n}) codes {len(seq) + 1} stripes, the projector needs "
                           f"{n_stripes}; raise k or n, or widen the stripes")
    colours = np.zeros(n_stripes, dtype=np.int64)
    if n_stripes > 1:
        colours[1:] = np.cumsum(1 + seq[: n_stripes - 1]) % (k + 1)
    return colours


@dataclass(frozen=True)
class PatternSpec:
    """What was projected: method, projector size and options. JSON round trip with to_dict/from_dict."""

    method: str
    width: int                      # projector width in pixels
    height: int                     # projector height in pixels
    axes: tuple[str, ...] = ("columns", "rows")  # coded axes, for coded methods
    options: dict = field(default_factory=dict, hash=False, compare=False)

    def __post_init__(self) -> None:
        if not isinstance(self.method, str) or self.method not in PATTERN_METHODS:
            raise PatternError(f"unknown pattern method {show(self.method)}; known: {', '.join(PATTERN_METHODS)}")
        for name in ("width", "height"):
            object.__setattr__(self, name, whole_number(getattr(self, name), f"pattern {name} (projector pixels)",
                                                  1, MAX_IMAGE_SIDE_PX))
        if not isinstance(self.axes, (tuple, list)) or not all(isinstance(a, str) for a in self.axes):
            raise PatternError(f"pattern axes must be a non-empty subset of {_AXES}, found {show(self.axes)}")
        bad = [a for a in self.axes if a not in _AXES]
        if bad or not self.axes or len(set(self.axes)) != len(self.axes):
            raise PatternError(f"pattern axes must be a non-empty subset of {_AXES}, found {self.axes}")
        axes = tuple(a for a in _AXES if a in self.axes)
        if self.method == "debruijn":
            axes = ("columns",)
        if not isinstance(self.options, dict):
            raise PatternError(f"pattern options must be an object, found {show(self.options)}")
        for key, value in self.options.items():       # NaN or infinity nowhere, used by the method or not
            if not _all_finite(value):
                raise PatternError(f"pattern options: {key}: expected finite numbers, found {show(value)}")
        opts = {**_DEFAULT_OPTIONS.get(self.method, {}), **dict(self.options)}
        object.__setattr__(self, "axes", axes)
        if self.method == "phase":
            opts["periods"] = {a: self._periods(opts.get("periods"), a) for a in axes}
            if "rounding" in opts and opts["rounding"] not in _ROUNDINGS:
                raise PatternError(f"phase rounding must be one of {', '.join(_ROUNDINGS)} (\"down\": SLStudio's "
                                   f"truncated frames), found {show(opts['rounding'])}")
        if self.method in FRINGE_METHODS:
            opts = check_fringe_options(self.method, opts, self.width, self.height, axes)
        if self.method == "hybrid":
            period = opts["period"]
            if not (is_number(period) and 0 < period <= MAX_IMAGE_SIDE_PX):
                raise PatternError(f"hybrid period must be a number in (0, {MAX_IMAGE_SIDE_PX}] projector px, "
                                   f"found {show(period)}")
            if "min_bit" in opts:
                m = whole_number(opts["min_bit"], "hybrid min_bit (the finest Gray bit projected)", 0,
                                 min(self.bits(a) for a in axes) - 1)
                if 2 ** m > period / 2:
                    raise PatternError(f"hybrid min_bit {m}: a Gray code without bits below {m} names blocks of "
                                       f"{2 ** m} px, more than half the {period:g} px period; expected a min_bit with "
                                       f"2**min_bit <= period / 2")
                opts["min_bit"] = m
        for key in ("steps", "fine_steps"):
            if key in opts and self.method in ("phase", "hybrid"):
                opts[key] = whole_number(opts[key], f"phase shifting {key}", 3, MAX_PHASE_STEPS)
        if self.method == "debruijn":
            k = whole_number(opts["k"], "de Bruijn k (stripe colours - 1)", 2, len(DEBRUIJN_PALETTE) - 1)
            n = whole_number(opts["n"], "de Bruijn n (window length)", 1, 64)
            if k ** n > MAX_DEBRUIJN_LENGTH:
                raise PatternError(f"de Bruijn B(k={k}, n={n}) has k**n = {k ** n} entries, expected at most "
                                   f"{MAX_DEBRUIJN_LENGTH}; lower n")
            w = whole_number(opts["stripe_width"], "de Bruijn stripe_width (projector px)", 1, self.width)
            opts.update(k=k, n=n, stripe_width=w)
            debruijn_stripe_colours(k, n, -(-self.width // w))  # raises if too short
        object.__setattr__(self, "options", opts)
        check_budget(self.width * self.height * (3 if self.is_colour else 1),
                     f"a {self.width}x{self.height} {self.method} pattern frame")

    def _periods(self, given, axis: str) -> list:
        """The checked phase periods of ``axis``: finite, positive, the first >= the axis size."""
        ps = list(self._default_periods(axis)) if given is None else given.get(axis) if isinstance(given, dict) \
            else given
        size = self._size(axis)
        if not (isinstance(ps, (list, tuple)) and 1 <= len(ps) <= MAX_PHASE_LEVELS and all(map(is_number, ps))
                and ps[0] >= size and all(p > 0 for p in ps)):
            raise PatternError(f"phase periods for {axis} must be 1 to {MAX_PHASE_LEVELS} finite numbers > 0, the "
                               f"first >= {size} px (absolute phase), found {show(ps)}")
        return list(ps)

    def _size(self, axis: str) -> int:
        return self.width if axis == "columns" else self.height

    def _default_periods(self, axis: str) -> tuple[float, ...]:
        size = self._size(axis)
        return (float(size), size / 8.0, size / 64.0)

    # -------------------------------------------------------------- frame list
    def bits(self, axis: str) -> int:
        """Number of Gray-code bits for an axis."""
        return n_bits_for(self._size(axis))

    @property
    def min_gray_bit(self) -> int:
        """The finest Gray bit projected: hybrid's ``min_bit`` option, else 0 (every bit)."""
        return int(self.options.get("min_bit", 0)) if self.method == "hybrid" else 0

    @property
    def xor_base(self) -> int | None:
        """Base bit of an XOR code (0 for XOR-02, 1 for XOR-04), else None."""
        return {"xor02": 0, "xor04": 1}.get(self.method)

    def phase_plan(self, axis: str) -> list[tuple[float, int]]:
        """(period in projector px, steps) for each phase level of ``axis``, coarse to fine."""
        o = self.options
        if self.method == "hybrid":
            return [(float(o["period"]), int(o["steps"]))]
        if self.method == "phase":
            ps = [float(p) for p in o["periods"][axis]]
            return [(p, int(o["fine_steps"]) if i == len(ps) - 1 else int(o["steps"])) for i, p in enumerate(ps)]
        return []

    @property
    def frame_names(self) -> list[str]:
        """One name per frame, in rangekit's projection order."""
        m = self.method
        if m in ("white", "black"):
            return [m]
        if m == "debruijn":
            return ["debruijn"]
        if m in FRINGE_METHODS:
            return fringe_frame_names(m, self.axes, self.options)
        names = ["white", "black"]
        for axis in self.axes:
            prefix = "col" if axis == "columns" else "row"
            if m in _BINARY:
                for b in range(self.bits(axis) - 1, self.min_gray_bit - 1, -1):
                    names += [f"{prefix}_b{b}", f"{prefix}_b{b}_inv"]
        for axis in self.axes:
            prefix = "col" if axis == "columns" else "row"
            for period, steps in self.phase_plan(axis):
                names += [f"{prefix}_p{period:g}_s{s}" for s in range(steps)]
        return names

    def frame_names_in(self, order: str = "rangekit") -> list[str]:
        """Frame names in a capture order: "rangekit", or "opencv" (GrayCodePattern: pairs, white, black)."""
        if order not in _ORDERS:
            raise PatternError(f"unknown capture order {order!r}; known: {', '.join(_ORDERS)}")
        names = self.frame_names
        if order == "opencv":
            if self.method != "graycode":
                raise PatternError(f"order='opencv' exists only for graycode captures, not {self.method!r}")
            return [n for n in names if n not in ("white", "black")] + ["white", "black"]
        return names

    @property
    def n_frames(self) -> int:
        return len(self.frame_names)

    @property
    def frame_files(self) -> list[str]:
        """The file of each frame in a capture folder: ``000.png``, ``001.png``, ..."""
        return [f"{i:03d}.png" for i in range(self.n_frames)]

    @property
    def is_colour(self) -> bool:
        return self.method == "debruijn"

    def frame(self, index: int, *, order: str = "rangekit") -> np.ndarray:
        """Frame ``index`` (in ``order``) as a uint8 image, (height, width) or (height, width, 3)."""
        names = self.frame_names_in(order)
        if not 0 <= index < len(names):
            raise PatternError(f"pattern {self.method!r} has {len(names)} frames; frame {index} does not exist")
        return self.frame_by_name(names[index])

    def frame_by_name(self, name: str) -> np.ndarray:
        H, W = self.height, self.width
        if self.method in FRINGE_METHODS:
            return fringe_frame(self.method, name, W, H, self.options)
        if name == "white":
            return np.full((H, W), 255, np.uint8)
        if name == "black":
            return np.zeros((H, W), np.uint8)
        if name == "debruijn":
            o = self.options
            w = int(o["stripe_width"])
            colours = debruijn_stripe_colours(int(o["k"]), int(o["n"]), -(-W // w))
            line = DEBRUIJN_PALETTE[colours[np.arange(W) // w]] * np.uint8(255)
            return np.broadcast_to(line[None], (H, W, 3)).copy()
        parts = name.split("_")
        prefix = parts[0]
        n = W if prefix == "col" else H
        u = np.arange(n)
        if parts[1].startswith("b"):
            b = int(parts[1][1:])
            code = gray_encode(u)
            stripe = (code >> b) & 1
            base = self.xor_base
            if base is not None and b > base:
                stripe ^= (code >> base) & 1
            stripe = stripe.astype(bool) ^ name.endswith("_inv")
            line = np.where(stripe, 255, 0).astype(np.uint8)
        else:
            period = float(parts[1][1:])
            s = int(parts[2][1:])
            steps = dict((f"{p:g}", st) for p, st in self.phase_plan("columns" if prefix == "col" else "rows"))
            n_steps = steps[f"{period:g}"]
            if self.options.get("rounding") == "down":  # the exact period, not its name's 6 digits
                exact = next(p for p, _ in self.phase_plan("columns" if prefix == "col" else "rows")
                             if f"{p:g}" == f"{period:g}")
                line = slstudio_phase_line(n, exact, slstudio_shift(s, n_steps))
            else:
                value = 0.5 + 0.5 * np.cos(2 * np.pi * u / period - 2 * np.pi * s / n_steps)
                line = np.rint(value * 255).astype(np.uint8)
        return np.broadcast_to(line[None, :] if prefix == "col" else line[:, None], (H, W)).copy()

    def frames(self, *, order: str = "rangekit") -> Iterator[np.ndarray]:
        for name in self.frame_names_in(order):
            yield self.frame_by_name(name)

    # -------------------------------------------------------------- serialisation
    def to_dict(self) -> dict:
        return {"method": self.method, "width": self.width, "height": self.height, "axes": list(self.axes),
                "options": dict(self.options), "frames": self.frame_names}

    @classmethod
    def from_dict(cls, data: dict, *, where: str = "pattern spec") -> "PatternSpec":
        """Inverse of :meth:`to_dict`; every problem is a PatternError starting with ``where``."""
        if not isinstance(data, dict):
            raise PatternError(f"{where}: expected a JSON object with method, width, height (and axes, options), "
                               f"found {show(data)}")
        missing = [k for k in ("method", "width", "height") if k not in data]
        if missing:
            raise PatternError(f"{where}: expected method, width, height (and axes, options); missing "
                               f"{', '.join(missing)}")
        axes = data.get("axes", _AXES)
        try:
            spec = cls(method=data["method"], width=data["width"], height=data["height"],
                       axes=tuple(axes) if isinstance(axes, list) else axes, options=data.get("options", {}))
        except PatternError as exc:
            raise PatternError(f"{where}: {exc}") from None
        frames = data.get("frames", spec.frame_names)
        if not isinstance(frames, list) or frames != spec.frame_names:
            n = len(frames) if isinstance(frames, list) else show(frames)
            raise PatternError(f"{where}: its frame list ({n} frames) does not match what "
                               f"method {spec.method!r} generates ({spec.n_frames} frames)")
        return spec

    def __eq__(self, other: object) -> bool:
        return isinstance(other, PatternSpec) and self.to_dict() == other.to_dict()

    def __hash__(self) -> int:
        return hash((self.method, self.width, self.height, self.axes))


def _all_finite(value) -> bool:
    """Whether every number in ``value`` (nested lists and objects) is finite."""
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, dict):
        return all(_all_finite(v) for v in value.values())
    if isinstance(value, (list, tuple)):
        return all(_all_finite(v) for v in value)
    return True


def make_pattern_spec(method: str, projector_size: tuple[int, int], **options) -> PatternSpec:
    """A spec for ``method`` on a projector of ``(width, height)`` pixels; options as in the module doc."""
    axes = options.pop("axes", _AXES)
    return PatternSpec(method=method, width=int(projector_size[0]), height=int(projector_size[1]),
                       axes=tuple(axes), options=options)
