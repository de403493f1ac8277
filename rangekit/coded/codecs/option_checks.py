"""The checks of a pattern set's options, shared by :mod:`rangekit.coded.patterns` and the tool codecs'
:mod:`rangekit.coded.codecs.fringes`: a value shown short in a message, a finite number, a whole number in a
range (PatternError naming the option, what was expected and what was found)."""

from __future__ import annotations

import math

import numpy as np

from rangekit.errors import PatternError

__all__ = ["show", "is_number", "whole_number"]


def show(value) -> str:
    """``repr(value)``, cut to 80 characters."""
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def is_number(value) -> bool:
    """A finite real number (not a bool)."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_)) \
        and math.isfinite(value)


def whole_number(value, what: str, lo: int, hi: int) -> int:
    """``value`` as an int in [lo, hi] (a whole number, int or float); PatternError naming ``what`` otherwise."""
    if not (is_number(value) and float(value).is_integer() and lo <= value <= hi):
        raise PatternError(f"{what} must be a whole number in {lo}..{hi}, found {show(value)}")
    return int(value)
