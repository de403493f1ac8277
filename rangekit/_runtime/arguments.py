"""The front door's argument checks (issue 48): every public function and option class of ``rangekit`` calls these
at its top, so a wrong argument is refused before any work, with a message naming the argument, what it got (a
short repr, an array by its shape) and what it expects: ``voxel: expected a finite number > 0, found '1' (str)``.

A value of the wrong type (None where a value is needed, a string where a number or a flag is) is an
:class:`~rangekit.errors.ArgumentTypeError`, an InputError that is also a TypeError; a value of the right type
that is not allowed (NaN, out of range, empty) an :class:`~rangekit.errors.InputError`. ``error=`` raises that
subclass for both instead (``ScanOptions``' OptionError). Booleans are real bools (``"no"`` is not False);
paths are ``str`` or ``os.PathLike``, not empty; numbers are finite. A valid value is returned unchanged.
"""

from __future__ import annotations

import math
import numbers
import os
from collections.abc import Iterable, Mapping
from typing import NoReturn

import numpy as np

from rangekit.errors import ArgumentTypeError, InputError

__all__ = ["found", "refuse", "is_int", "is_number", "check_bool", "check_number", "check_path", "check_text",
           "check_choice", "check_callable", "check_instance", "check_items", "check_vector", "as_array",
           "as_points", "check_pose"]

#: The most characters of a value's repr a message quotes.
REPR_LIMIT = 60


def found(value) -> str:
    """What a message says was found: a short repr and the type (an array by its shape and dtype)."""
    if isinstance(value, np.ndarray):
        return f"an array of shape {value.shape} {value.dtype}"
    text = repr(value)
    if len(text) > REPR_LIMIT:
        text = text[:REPR_LIMIT - 3] + "..."
    return text if value is None or isinstance(value, bool) else f"{text} ({type(value).__name__})"


def refuse(name: str, value, expected: str, *, wrong_type: bool = False, error: type | None = None) -> NoReturn:
    """Raise ``NAME: expected EXPECTED, found VALUE``: ``error`` if given, else an ArgumentTypeError for a value of
    the wrong type and an InputError for one of the right type that is not allowed."""
    cls = error or (ArgumentTypeError if wrong_type else InputError)
    raise cls(f"{name}: expected {expected}, found {found(value)}")


def is_int(value) -> bool:
    """A whole number (Python's or numpy's), not a bool."""
    return isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_))


def is_number(value) -> bool:
    """A real number (Python's or numpy's), not a bool; NaN included (see :func:`check_number`)."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def check_bool(name: str, value, *, error: type | None = None):
    """``value`` if it is True or False (numpy's bool too): ``"no"``, 0 and None are refused."""
    if not isinstance(value, (bool, np.bool_)):
        refuse(name, value, "True or False", wrong_type=True, error=error)
    return value


def _range_text(lo, hi, lo_open: bool, hi_open: bool, integer: bool) -> str:
    if lo is not None and hi is not None:
        if integer and not (lo_open or hi_open):
            return f" in {lo}..{hi}"
        return f" in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"
    if lo is not None:
        return f" {'>' if lo_open else '>='} {lo:g}"
    if hi is not None:
        return f" {'<' if hi_open else '<='} {hi:g}"
    return ""


def check_number(name: str, value, *, lo=None, hi=None, lo_open: bool = False, hi_open: bool = False,
                 integer: bool = False, optional: bool = False, unit: str = "", error: type | None = None):
    """``value`` if it is a finite number (``integer``: a whole number) within the bounds (``lo_open``: ``> lo``);
    None too when ``optional``. ``unit`` is said after the range (``"metres"``)."""
    if value is None and optional:
        return value
    expected = ("an integer" if integer else "a finite number") + _range_text(lo, hi, lo_open, hi_open, integer)
    expected += f" ({unit})" if unit else ""
    expected += " or None" if optional else ""
    if not (is_int(value) if integer else is_number(value)):
        refuse(name, value, expected, wrong_type=True, error=error)
    if not math.isfinite(value) or (lo is not None and (value <= lo if lo_open else value < lo)) or \
            (hi is not None and (value >= hi if hi_open else value > hi)):
        refuse(name, value, expected, error=error)
    return value


def check_path(name: str, value, *, optional: bool = False, what: str = "a path", error: type | None = None):
    """``value`` if it is a ``str`` or ``os.PathLike`` that is not empty (None too when ``optional``)."""
    if value is None and optional:
        return value
    expected = f"{what} (str or os.PathLike, not empty)" + (" or None" if optional else "")
    if not isinstance(value, (str, os.PathLike)):
        refuse(name, value, expected, wrong_type=True, error=error)
    text = os.fspath(value)
    if not isinstance(text, str):
        refuse(name, value, expected, wrong_type=True, error=error)
    if not text:
        refuse(name, value, expected, error=error)
    return value


def check_text(name: str, value, *, optional: bool = False, what: str = "a string",
               error: type | None = None):
    """``value`` if it is a ``str`` that is not empty (None too when ``optional``)."""
    if value is None and optional:
        return value
    expected = f"{what} (not empty)" + (" or None" if optional else "")
    if not isinstance(value, str):
        refuse(name, value, expected, wrong_type=True, error=error)
    if not value:
        refuse(name, value, expected, error=error)
    return value


def check_choice(name: str, value, choices, *, optional: bool = False, error: type | None = None):
    """``value`` if it is one of ``choices`` (strings; None too when ``optional``)."""
    if value is None and optional:
        return value
    expected = "one of " + ", ".join(map(repr, choices)) + (" or None" if optional else "")
    if not isinstance(value, str):
        refuse(name, value, expected, wrong_type=True, error=error)
    if value not in choices:
        refuse(name, value, expected, error=error)
    return value


def check_callable(name: str, value, *, optional: bool = True, error: type | None = None):
    """``value`` if it can be called (None too when ``optional``, the default: a callback left out)."""
    if (value is None and optional) or callable(value):
        return value
    refuse(name, value, "a callable" + (" or None" if optional else ""), wrong_type=True, error=error)


def check_instance(name: str, value, types, expected: str, *, optional: bool = False, error: type | None = None):
    """``value`` if it is an instance of ``types`` (None too when ``optional``); ``expected`` says what that is."""
    if (value is None and optional) or isinstance(value, types):
        return value
    refuse(name, value, expected + (" or None" if optional else ""), wrong_type=True, error=error)


def check_items(name: str, value, expected: str, *, min_items: int = 0, optional: bool = False,
                error: type | None = None) -> list | None:
    """``value``'s items as a list, if it is a list, tuple, array or other iterable of them (not a string, bytes
    or a mapping) with at least ``min_items``; ``expected`` says what the items are."""
    if value is None and optional:
        return value
    text = f"{expected}" + (f", at least {min_items}" if min_items else "") + (" or None" if optional else "")
    if isinstance(value, (str, bytes, Mapping)) or not isinstance(value, Iterable):
        refuse(name, value, text, wrong_type=True, error=error)
    items = list(value)
    if len(items) < min_items:
        refuse(name, value, text, error=error)
    return items


def check_vector(name: str, value, size: int, *, nonzero: bool = False, optional: bool = False,
                 error: type | None = None):
    """``value`` if it holds ``size`` finite numbers (``nonzero``: not all zero); None too when ``optional``."""
    if value is None and optional:
        return value
    expected = f"{size} finite numbers" + (", not all zero" if nonzero else "") + (" or None" if optional else "")
    if isinstance(value, (str, bytes, Mapping)) or not isinstance(value, Iterable):
        refuse(name, value, expected, wrong_type=True, error=error)
    items = list(value)
    if not all(is_number(v) for v in items):
        refuse(name, value, expected, wrong_type=True, error=error)
    if len(items) != size or not all(math.isfinite(v) for v in items) or (nonzero and not any(items)):
        refuse(name, value, expected, error=error)
    return value


def as_array(name: str, value, expected: str, *, dtype=np.float64, error: type | None = None) -> np.ndarray:
    """``value`` as a numpy array of ``dtype`` (``np.asarray``: an array of that dtype is not copied), refused when it
    is None, a string, a mapping or not numeric; the caller checks the shape. ``expected`` names the shape."""
    if value is None or isinstance(value, (str, bytes, Mapping)):
        refuse(name, value, expected, wrong_type=True, error=error)
    try:
        return np.asarray(value, dtype=dtype)
    except (TypeError, ValueError):
        refuse(name, value, expected, wrong_type=True, error=error)


def as_points(name: str, value, *, rows: str = "N", error: type | None = None) -> np.ndarray:
    """``value`` as a float64 (N, 3) array (``rows`` names N in the message: ``"V"`` for vertices)."""
    expected = f"an ({rows}, 3) array"
    P = as_array(name, value, expected, error=error)
    if P.ndim != 2 or P.shape[1] != 3:
        refuse(name, P, expected, error=error)
    return P


def check_pose(name: str, value, *, count: int | None = None, optional: bool = False,
               error: type | None = None) -> np.ndarray | None:
    """``value`` as a float64 (4, 4) matrix of finite numbers (``count``: (count, 4, 4), one per view); None too
    when ``optional``."""
    if value is None and optional:
        return None
    shape = (4, 4) if count is None else (count, 4, 4)
    expected = f"a {shape} array of finite numbers" + (" or None" if optional else "")
    T = as_array(name, value, expected, error=error)
    if T.shape != shape or not np.isfinite(T).all():
        refuse(name, value if not isinstance(value, np.ndarray) else T, expected, error=error)
    return T
