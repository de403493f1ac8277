"""Paths a browser names, confined to the sessions folder (``rangekit ui --sessions DIR``).

A page names a session or a file by its path relative to the sessions folder. Anything that would lead out
of it is refused before any file is opened: an absolute path, a ``..`` part, a NUL byte, or a symbolic link
anywhere on the way whose target lies outside the folder.
"""

from __future__ import annotations

from pathlib import Path, PurePosixPath

from rangekit.errors import RangekitError

__all__ = ["PathRefused", "confined"]


class PathRefused(RangekitError):
    """A path from a page that would leave the sessions folder."""


def confined(root: Path, name: str) -> Path:
    """``root / name``, resolved, when it lies inside ``root`` (itself resolved); :class:`PathRefused` naming
    ``name`` otherwise. ``name``: a relative POSIX path as a page sends it ('' or '.' is ``root`` itself)."""
    root = Path(root).resolve()
    if not isinstance(name, str) or "\x00" in name or "\\" in name:
        raise PathRefused(f"path {name!r}: refused (a relative path under the sessions folder, '/' separated)")
    rel = PurePosixPath(name)
    if rel.is_absolute() or name.startswith("~"):
        raise PathRefused(f"path {name!r}: refused (absolute; name it relative to the sessions folder)")
    if any(part == ".." for part in rel.parts):
        raise PathRefused(f"path {name!r}: refused ('..' leads out of the sessions folder)")
    target = root.joinpath(*rel.parts).resolve()   # follows every link on the way
    if target != root and root not in target.parents:
        raise PathRefused(f"path {name!r}: refused (a link out of the sessions folder, to {target})")
    return target
