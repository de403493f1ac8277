"""The names a page may give a new folder under ``--sessions`` (a scan's session, a saved registration), checked
before anything starts: at most :data:`MAX_NAME` characters, letters, digits and ``. _ - +``, beginning with a
letter or a digit (a leading dot would hide it, and ``.registering`` is the registration's staging folder), no
separator or backslash."""

from __future__ import annotations

from rangekit.errors import RangekitError

__all__ = ["MAX_NAME", "check_folder_name"]

#: The longest folder name a page may give (characters); the files inside add their own names to it.
MAX_NAME = 100
_ALLOWED = "._-+"


def check_folder_name(name, field: str = "name") -> str:
    """``name`` when it is a folder name a page may create; one line naming ``field`` otherwise."""
    if not isinstance(name, str):
        raise RangekitError(f"{field}: expected a folder name (a string), found {name!r}"[:200])
    if not name:
        raise RangekitError(f"{field}: empty; give the folder a name")
    if len(name) > MAX_NAME:
        raise RangekitError(f"{field}: {len(name)} characters; at most {MAX_NAME}")
    if not name[0].isalnum():
        raise RangekitError(f"{field}: {name!r}: begins with {name[0]!r}; begin with a letter or a digit")
    bad = next((c for c in name if not (c.isalnum() or c in _ALLOWED)), None)
    if bad is not None:
        raise RangekitError(f"{field}: {name!r}: {bad!r} not allowed; use letters, digits and {' '.join(_ALLOWED)}")
    return name
