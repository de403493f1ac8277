"""The simulator's built-in objects as a table (``rangekit sim objects``): name, size, triangle count and
what makes each one hard to scan."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.errors import RangekitError

__all__ = ["ObjectInfo", "list_objects", "format_objects"]


@dataclass(frozen=True)
class ObjectInfo:
    """One built-in object as its builder makes it by default."""

    name: str
    size_mm: tuple[float, float, float] | None   # bounding box extent along x, y, z (object frame, z up), mm
    triangles: int | None
    note: str                                    # what makes it hard (or what it is for)
    unavailable: str | None = None               # why it cannot be built here (the bunny without its data)


def list_objects() -> list[ObjectInfo]:
    """Every ``BUILTIN_OBJECTS`` entry, built with its defaults, in registry order."""
    from rangekit.sim.scene.objects import BUILTIN_OBJECTS, OBJECT_NOTES

    rows = []
    for name, build in BUILTIN_OBJECTS.items():
        note = OBJECT_NOTES.get(name, "")
        try:
            obj = build()
        except RangekitError as exc:
            rows.append(ObjectInfo(name, None, None, note, str(exc)))
            continue
        size = np.ptp(obj.vertices, axis=0) * 1e3
        rows.append(ObjectInfo(name, tuple(float(s) for s in size), len(obj.triangles), note))
    return rows


def format_objects(rows: list[ObjectInfo]) -> list[str]:
    """Lines of a fixed-width table: name, size (mm), triangles, what makes it hard."""
    lines = [f"{'name':<9} {'size x y z (mm)':<21} {'triangles':>9}  what makes it hard"]
    for r in rows:
        size = "unavailable" if r.size_mm is None else " x ".join(f"{s:.0f}" for s in r.size_mm)
        tris = "-" if r.triangles is None else f"{r.triangles:,}"
        lines.append(f"{r.name:<9} {size:<21} {tris:>9}  {r.note}")
        if r.unavailable:
            lines.append(f"{'':<9} ({r.unavailable})")
    return lines
