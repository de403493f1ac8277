"""A rig file's text for people: JSON indented by two spaces, each matrix and vector on one line
(``"K": [[1000.0, 0.0, 639.5], [0.0, 1000.0, 399.5], [0.0, 0.0, 1.0]]``), floats written exactly (``repr``),
so the text reads back to the same numbers. Used by ``rangekit rig init`` and ``rangekit rig import``."""

from __future__ import annotations

import json
from numbers import Number

__all__ = ["rig_json_text"]


def _numeric(value) -> bool:
    """A list of numbers, or a list of such lists (a vector or a matrix)."""
    return isinstance(value, list) and bool(value) and all(
        (isinstance(v, Number) and not isinstance(v, bool)) or (isinstance(v, list) and _numeric(v)) for v in value)


def _dump(value, indent: int) -> str:
    pad, inner = " " * indent, " " * (indent + 2)
    if isinstance(value, dict) and value:
        items = [f"{inner}{json.dumps(str(k))}: {_dump(v, indent + 2)}" for k, v in value.items()]
        return "{\n" + ",\n".join(items) + f"\n{pad}}}"
    if isinstance(value, list) and value and not _numeric(value):
        return "[\n" + ",\n".join(f"{inner}{_dump(v, indent + 2)}" for v in value) + f"\n{pad}]"
    return json.dumps(value, allow_nan=False)


def rig_json_text(data: dict) -> str:
    """``data`` (a rig file's plain JSON types) as text ending with a newline; matrices on one line each."""
    return _dump(data, 0) + "\n"
