"""What a laser-line scan takes at each turntable step: the laser-off frame, then each laser alone.

A session records it as its ``pattern`` (``{"method": "laser", "lasers": 2}``), where a coded-light
session records its :class:`~rangekit.coded.patterns.PatternSpec`; each view folder is then a laser
capture folder (``off.png``, ``laser0.png``, ... : :mod:`rangekit.formats.laser_capture`).
"""

from __future__ import annotations

from dataclasses import dataclass

from rangekit.errors import PatternError

__all__ = ["LaserSequence", "LASER_METHOD", "MAX_LASERS"]

LASER_METHOD = "laser"
#: Line lasers a rig may have (the boards rangekit drives have two; Horus firmware numbers up to 4).
MAX_LASERS = 8


@dataclass(frozen=True)
class LaserSequence:
    """``n_lasers`` line lasers: frame 0 with every laser off, frame k + 1 with laser k alone on."""

    n_lasers: int

    def __post_init__(self) -> None:
        if isinstance(self.n_lasers, bool) or not isinstance(self.n_lasers, int) or not 1 <= self.n_lasers <= MAX_LASERS:
            raise PatternError(f"a laser sequence needs 1 to {MAX_LASERS} lasers, found {self.n_lasers!r}")

    @property
    def method(self) -> str:
        return LASER_METHOD

    @property
    def frame_names(self) -> list[str]:
        """``["off", "laser0", "laser1", ...]``."""
        return ["off"] + [f"laser{k}" for k in range(self.n_lasers)]

    @property
    def frame_files(self) -> list[str]:
        """``["off.png", "laser0.png", ...]``, the files of a laser capture folder."""
        return [f"{name}.png" for name in self.frame_names]

    @property
    def n_frames(self) -> int:
        return self.n_lasers + 1

    def lit(self, frame: int) -> int | None:
        """Index (in the rig's ``lasers``) of the laser on in ``frame``; None for the laser-off frame."""
        return None if frame == 0 else frame - 1

    def to_dict(self) -> dict:
        return {"method": LASER_METHOD, "lasers": self.n_lasers, "frames": self.frame_names}

    @classmethod
    def from_dict(cls, data, *, where: str = "laser sequence") -> "LaserSequence":
        """Inverse of :meth:`to_dict`; a problem is a PatternError starting with ``where``."""
        if not isinstance(data, dict) or data.get("method") != LASER_METHOD or "lasers" not in data:
            raise PatternError(f"{where}: expected {{'method': 'laser', 'lasers': N}}, found {str(data)[:120]}")
        extra = sorted(set(data) - {"method", "lasers", "frames"})
        if extra:
            raise PatternError(f"{where}: unknown field(s) {', '.join(map(repr, extra))}; expected method, lasers")
        try:
            seq = cls(data["lasers"])
        except PatternError as exc:
            raise PatternError(f"{where}: {exc}") from None
        if "frames" in data and data["frames"] != seq.frame_names:
            raise PatternError(f"{where}: frames: expected {seq.frame_names}, found {str(data['frames'])[:120]}")
        return seq
