"""Where a simulated session's object comes from: a built-in name, or a mesh file inside the session folder."""

from __future__ import annotations

from pathlib import Path

from rangekit.errors import ConfigError

__all__ = ["object_source"]


def object_source(folder: Path, value: str, path: Path) -> str:
    """A simulated session's ``simulator.object`` as the simulator takes it: a built-in name (no ``/``,
    no ``.``) as is, else the path of a mesh file inside ``folder`` (``value`` relative to it, no ``..``,
    no symbolic link out of it). ConfigError naming ``path`` and the reason otherwise."""
    if not any(c in value for c in "/\\."):
        return value
    p = Path(value)
    why = None
    if p.is_absolute():
        why = "an absolute path"
    elif ".." in p.parts:
        why = "a path with '..'"
    else:
        full = folder / p
        try:
            inside = full.resolve().is_relative_to(folder.resolve())
        except (OSError, RuntimeError, ValueError):
            inside = False
        if not inside:
            why = "a link out of the session folder"
        elif not full.is_file():
            why = "not a file in the session folder"
    if why is not None:
        raise ConfigError(f"{path}: simulator.object: expected a built-in object name or a mesh file inside the "
                          f"session folder (such as 'object/bunny.ply'), not {why}, found {value[:80]!r}")
    return str(folder / p)
