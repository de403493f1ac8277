"""What a laser scan's processing found per laser (summary.json's ``laser``), as typed values: counts only (points,
steps, rows), so nothing is converted at the file boundary; ``to_dict`` writes the keys in the order the file has
always had them."""

from __future__ import annotations

from dataclasses import dataclass, field

__all__ = ["LaserFigures", "LaserSummary"]


@dataclass(frozen=True)
class LaserFigures:
    """One laser over the scan: its ``name``, the ``points`` it placed on the object, the ``steps_without_line``,
    the ``table_points`` dropped as the turntable top, and its ``rejected_rows`` by reason (``saturated``,
    ``double``, ...: rows of its frames)."""

    name: str
    points: int
    steps_without_line: int
    table_points: int
    rejected_rows: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"name": self.name, "points": self.points, "steps_without_line": self.steps_without_line,
                "table_points": self.table_points, "rejected_rows": dict(self.rejected_rows)}

    @classmethod
    def from_dict(cls, d: dict) -> "LaserFigures":
        return cls(d["name"], int(d["points"]), int(d["steps_without_line"]), int(d.get("table_points", 0)),
                   dict(d.get("rejected_rows", {})))

    def summary(self) -> str:
        """This laser's part of the end-of-run summary's registration line."""
        saturated = self.rejected_rows.get("saturated", 0)
        return (f"{self.name}: {self.points:,} points, no line in {self.steps_without_line} step(s)"
                + (f", {saturated:,} saturated rows" if saturated else ""))


@dataclass(frozen=True)
class LaserSummary:
    """A laser scan's processing: each laser's :class:`LaserFigures` and the ``peak_method`` that found the lines
    (:func:`rangekit.laser.detect_peaks`)."""

    lasers: tuple[LaserFigures, ...]
    peak_method: str

    def to_dict(self) -> dict:
        return {"lasers": [laser.to_dict() for laser in self.lasers], "peak_method": self.peak_method}

    @classmethod
    def from_dict(cls, d: dict) -> "LaserSummary":
        return cls(tuple(LaserFigures.from_dict(x) for x in d["lasers"]), str(d.get("peak_method", "gaussian")))
