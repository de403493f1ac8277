"""The JSON fields a page sends, each checked for its type (and range) before any job sees it: a wrong one is a
400 naming the field, what it got and what it expects (``paused: expected true or false, found 'no'``).

A spec maps each field a request may carry to its check and default; a field the spec does not name is refused
too, so a misspelt field is never silently ignored.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from rangekit.errors import RangekitError

__all__ = ["Field", "flag", "number", "take", "text", "texts", "whole"]

_MISSING = object()
#: The longest text field accepted (characters); names and options are short.
MAX_TEXT = 1000


def _shown(value) -> str:
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + "..."


@dataclass(frozen=True)
class Field:
    """One field: ``check(name, value) -> value``; ``default``: its value when absent (``_MISSING``: required)."""

    check: Any
    default: Any = _MISSING


def _text(name, value):
    if not isinstance(value, str):
        raise RangekitError(f"{name}: expected a string, found {_shown(value)}")
    if len(value) > MAX_TEXT:
        raise RangekitError(f"{name}: expected at most {MAX_TEXT} characters, found {len(value)}")
    return value


def text(default=_MISSING) -> Field:
    return Field(_text, default)


def _flag(name, value):
    if not isinstance(value, bool):
        raise RangekitError(f"{name}: expected true or false, found {_shown(value)}")
    return value


def flag(default=_MISSING) -> Field:
    return Field(_flag, default)


def number(lo: float, hi: float, default=_MISSING, unit: str = "") -> Field:
    def check(name, value):
        if (isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value)
                or not lo <= value <= hi):
            raise RangekitError(f"{name}: expected a number {lo:g} to {hi:g}{unit}, found {_shown(value)}")
        return float(value)
    return Field(check, default)


def whole(lo: int, hi: int, default=_MISSING, nullable: bool = False) -> Field:
    def check(name, value):
        if value is None and nullable:
            return None
        if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
            raise RangekitError(f"{name}: expected a whole number {lo}-{hi}{' or null' if nullable else ''}, "
                                f"found {_shown(value)}")
        return value
    return Field(check, default)


def texts(most: int, default=_MISSING) -> Field:
    def check(name, value):
        if not isinstance(value, list) or len(value) > most or not all(isinstance(v, str) for v in value):
            raise RangekitError(f"{name}: expected a list of at most {most} strings, found {_shown(value)}")
        return [_text(name, v) for v in value]
    return Field(check, default)


def take(body: dict, spec: dict[str, Field], what: str) -> dict:
    """The fields of ``body`` by ``spec``, checked, defaults filled in; one line naming the first bad one."""
    unknown = sorted(set(body) - set(spec))
    if unknown:
        raise RangekitError(f"{what}: {_shown(unknown[0])}: not a field here; expected {', '.join(spec) or 'none'}")
    out = {}
    for name, field in spec.items():
        if name in body:
            out[name] = field.check(name, body[name])
        elif field.default is _MISSING:
            raise RangekitError(f"{name}: missing; {what} needs it")
        else:
            out[name] = field.default
    return out
