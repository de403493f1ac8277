"""Where a simulated scan's error comes from, view by view (summary.json's ``view_errors``), as typed values in SI
units: distances in metres, angles in radians; decoding errors in projector pixels. The file keeps its schema's
keys and units (``rms_mm``, ``rotation_deg``), converted only by ``to_list`` and ``from_list``, so the bytes are
those the per-view dicts in mm wrote (a distance is computed in metres and multiplied by 1e3 once, as before).
The simulator measures them (:mod:`rangekit.sim.truth.view_errors`); the report and the summary show them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["DistanceStats", "CloudErrors", "DecodingErrors", "PoseErrors", "ViewError", "ViewErrors"]


def _mm(metres: float | None) -> float | None:
    return None if metres is None else metres * 1e3


def _m(mm: float | None) -> float | None:
    return None if mm is None else mm / 1e3


@dataclass(frozen=True)
class DistanceStats:
    """Point-to-true-surface distances of a set of points: ``rms``, ``p95``, ``max`` (metres; None without
    points) over ``n`` points."""

    rms: float | None
    p95: float | None
    max: float | None
    n: int

    def to_dict(self) -> dict:
        return {"rms_mm": _mm(self.rms), "p95_mm": _mm(self.p95), "max_mm": _mm(self.max), "n": self.n}

    @classmethod
    def from_dict(cls, d: dict) -> "DistanceStats":
        return cls(_m(d["rms_mm"]), _m(d["p95_mm"]), _m(d["max_mm"]), int(d["n"]))


@dataclass(frozen=True)
class CloudErrors:
    """A view's cloud against the true surface at its turntable angle: every point (``all``), those ``inside`` a
    surface and those at a depth ``edge``; ``edge_share`` the edge points' share of the squared error."""

    all: DistanceStats
    inside: DistanceStats
    edge: DistanceStats
    edge_share: float

    def to_dict(self) -> dict:
        return {**self.all.to_dict(), "inside": self.inside.to_dict(), "edge": self.edge.to_dict(),
                "edge_share": self.edge_share}

    @classmethod
    def from_dict(cls, d: dict) -> "CloudErrors":
        return cls(DistanceStats.from_dict(d), DistanceStats.from_dict(d["inside"]),
                   DistanceStats.from_dict(d["edge"]), d["edge_share"])


@dataclass(frozen=True)
class DecodingErrors:
    """The decoded projector columns against the true ones: ``rms_px``, ``p95_px`` (projector pixels; None without
    pixels) over ``n`` pixels."""

    rms_px: float | None
    p95_px: float | None
    n: int

    def to_dict(self) -> dict:
        return {"rms_px": self.rms_px, "p95_px": self.p95_px, "n": self.n}

    @classmethod
    def from_dict(cls, d: dict) -> "DecodingErrors":
        return cls(d["rms_px"], d["p95_px"], int(d["n"]))


@dataclass(frozen=True)
class PoseErrors:
    """The registered pose against the true turntable pose: ``rotation`` (radians), ``translation`` of the object's
    centre (metres), ``point_rms`` the RMS displacement it gives the view's points (metres; None without points)."""

    rotation: float
    translation: float
    point_rms: float | None

    def to_dict(self) -> dict:
        return {"rotation_deg": float(np.degrees(self.rotation)), "translation_mm": _mm(self.translation),
                "point_rms_mm": _mm(self.point_rms)}

    @classmethod
    def from_dict(cls, d: dict) -> "PoseErrors":
        return cls(float(np.radians(d["rotation_deg"])), _m(d["translation_mm"]), _m(d["point_rms_mm"]))


@dataclass(frozen=True)
class ViewError:
    """One view's breakdown: its name (or index), ``decoding`` (None when the decoded columns were not given),
    ``cloud`` and ``registration``."""

    view: str | int
    decoding: DecodingErrors | None
    cloud: CloudErrors
    registration: PoseErrors

    def to_dict(self) -> dict:
        return {"view": self.view, "decoding": None if self.decoding is None else self.decoding.to_dict(),
                "cloud": self.cloud.to_dict(), "registration": self.registration.to_dict()}

    @classmethod
    def from_dict(cls, d: dict) -> "ViewError":
        dec = d.get("decoding")
        return cls(d["view"], None if dec is None else DecodingErrors.from_dict(dec), CloudErrors.from_dict(d["cloud"]),
                   PoseErrors.from_dict(d["registration"]))


@dataclass(frozen=True)
class ViewErrors:
    """Every view's :class:`ViewError`, in the views' order (iterable, indexable, sized)."""

    views: tuple[ViewError, ...]

    def __iter__(self):
        return iter(self.views)

    def __len__(self) -> int:
        return len(self.views)

    def __getitem__(self, k: int) -> ViewError:
        return self.views[k]

    def to_list(self) -> list[dict]:
        """summary.json's ``view_errors``: one dict per view, in mm and degrees."""
        return [v.to_dict() for v in self.views]

    @classmethod
    def from_list(cls, items: list[dict]) -> "ViewErrors":
        return cls(tuple(ViewError.from_dict(d) for d in items))

    def summary_line(self) -> str:
        """One line of the end-of-run summary: the ranges over the views (mm and degrees here only)."""
        def span(values, fmt):
            values = [v for v in values if v is not None]
            return f"{min(values):{fmt}}-{max(values):{fmt}}" if values else "n/a"

        cloud = [v.cloud for v in self.views]
        reg = [v.registration for v in self.views]
        dec = [v.decoding.rms_px for v in self.views if v.decoding is not None]
        return (f"per view against the truth: cloud RMS {span([_mm(c.all.rms) for c in cloud], '.4f')} mm "
                f"(depth-edge points {span([100 * c.edge_share for c in cloud], '.0f')}% of the squared error), "
                f"decoding RMS {span(dec, '.3f')} px, registration within "
                f"{max(math.degrees(r.rotation) for r in reg):.4f} deg and "
                f"{max(r.translation * 1e3 for r in reg):.4f} mm of the true turntable poses")
