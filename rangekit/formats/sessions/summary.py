"""What processing a session produced (``summary.json``, schema ``rangekit.summary/1``), as typed values.

:func:`rangekit.app.process.process.process_session` writes it into the session folder last, after the mesh,
poses and merged cloud, so a folder holding ``summary.json`` holds all of them. Inside, every figure is in SI
units (metres, square and cubic metres, radians); the file keeps its schema's keys and units (``rmse_mm``,
``rotation_residual_deg``, ``area_m2``...), converted only by ``to_dict`` and ``from_dict``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from rangekit.formats.sessions.laser_summary import LaserSummary
from rangekit.formats.sessions.view_errors import ViewErrors
from rangekit.formats.sessions.files import MESH_FILE, SUMMARY_FILE, WATERTIGHT_FILE

__all__ = ["SUMMARY_SCHEMA", "Edge", "MeshFigures", "Accuracy", "ClosedAccuracy", "ProcessResult", "LaserSummary",
           "ViewErrors"]

SUMMARY_SCHEMA = "rangekit.summary/1"


@dataclass(frozen=True)
class Edge:
    """One view pair of the registration: ``rmse`` (metres) of its refinement, ``overlap`` (fraction of points),
    accepted or refused (``reason``); an accepted pair's synchronisation residuals, ``rotation_residual``
    (radians) and ``translation_residual`` (metres)."""

    i: int
    j: int
    rmse: float
    overlap: float
    accepted: bool
    reason: str = ""
    rotation_residual: float | None = None
    translation_residual: float | None = None

    def to_dict(self) -> dict:
        return {"i": self.i, "j": self.j, "rmse_mm": self.rmse * 1e3, "overlap": self.overlap,
                "accepted": self.accepted, "reason": self.reason,
                "rotation_residual_deg": None if self.rotation_residual is None else
                float(np.degrees(self.rotation_residual)),
                "translation_residual_mm": None if self.translation_residual is None else
                self.translation_residual * 1e3}

    @classmethod
    def from_dict(cls, d: dict) -> "Edge":
        rot, tr = d.get("rotation_residual_deg"), d.get("translation_residual_mm")
        return cls(int(d["i"]), int(d["j"]), d["rmse_mm"] / 1e3, d["overlap"], bool(d["accepted"]), d.get("reason", ""),
                   None if rot is None else float(np.radians(rot)), None if tr is None else tr / 1e3)


@dataclass(frozen=True)
class MeshFigures:
    """A mesh file processing wrote: its ``file`` name, size, ``watertight``, ``area`` (m^2), ``volume`` (m^3, a
    closed mesh's only), the ``fusion`` that made it; a closed mesh with the ``observed`` flag also its
    ``unobserved_vertices`` and ``unobserved_area`` (m^2)."""

    file: str
    vertices: int
    triangles: int
    watertight: bool
    area: float
    volume: float | None
    fusion: str
    unobserved_vertices: int | None = None
    unobserved_area: float | None = None

    def to_dict(self) -> dict:
        d = {"file": self.file, "vertices": self.vertices, "triangles": self.triangles, "watertight": self.watertight,
             "area_m2": self.area, "volume_m3": self.volume, "fusion": self.fusion}
        if self.unobserved_vertices is not None:
            d.update(unobserved_vertices=self.unobserved_vertices, unobserved_area_m2=self.unobserved_area)
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "MeshFigures":
        return cls(d["file"], int(d["vertices"]), int(d["triangles"]), bool(d["watertight"]), d["area_m2"],
                   d.get("volume_m3"), d["fusion"], d.get("unobserved_vertices"), d.get("unobserved_area_m2"))


@dataclass(frozen=True)
class ClosedAccuracy:
    """The closed mesh (mesh_watertight.ply) against the true surface: :class:`Accuracy`'s figures of the same
    names (metres; ``completeness`` and ``unobserved_area`` fractions)."""

    rms: float
    p95: float
    max: float
    completeness: float
    unobserved_area: float
    unobserved_rms: float
    rms_all: float

    def to_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True)
class Accuracy:
    """A mesh against the true surface (the simulator's truth, :mod:`rangekit.sim.truth.evaluate`). Distances in
    metres, angles in radians."""

    rms: float               # mesh -> true surface
    p95: float
    max: float
    completeness: float      # fraction of the visible true surface within ``tolerance`` of the mesh
    tolerance: float
    diagonal: float          # the true object's bounding-box diagonal
    visible_fraction: float  # share of the object's whole surface the views can see
    unobserved_area: float   # share of the mesh's area filled in where no view saw the truth
    unobserved_rms: float    # mesh -> true surface over that filled-in part
    rms_all: float           # mesh -> true surface over the whole mesh, filled-in parts included
    max_incidence: float     # radians: "can see" = facing camera and projector within this angle
    n_mesh_samples: int
    n_truth_samples: int
    cloud_rms: float | None = None   # the scan's merged cloud -> true surface, when given
    cloud_p95: float | None = None
    n_cloud: int | None = None
    completeness_whole: float | None = None   # fraction of the object's WHOLE surface within ``tolerance``
    watertight: ClosedAccuracy | None = None  # the closed mesh's figures, when it was measured too

    def to_dict(self) -> dict:
        d = {}
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "max_incidence":
                d["max_incidence_deg"] = round(math.degrees(v), 9)
            elif f.name == "watertight":
                if v is not None:
                    d["watertight"] = v.to_dict()
            else:
                d[f.name] = float(v) if isinstance(v, (float, np.floating)) else v
        return d

    @classmethod
    def from_dict(cls, d: dict) -> "Accuracy":
        values = {f.name: d.get(f.name) for f in fields(cls) if f.name not in ("max_incidence", "watertight")}
        closed = d.get("watertight")
        return cls(**values, max_incidence=math.radians(d["max_incidence_deg"]),
                   watertight=None if closed is None else ClosedAccuracy(**{f.name: closed.get(f.name)
                                                                            for f in fields(ClosedAccuracy)}))

    def __str__(self) -> str:
        return (f"RMS {self.rms * 1e3:.3f} mm ({self.rms / self.diagonal:.3%} of the {self.diagonal * 1e3:.0f} mm "
                f"diagonal), 95th percentile {self.p95 * 1e3:.3f} mm, max {self.max * 1e3:.3f} mm; completeness "
                f"{self.completeness:.1%} of the visible surface within {self.tolerance * 1e3:g} mm"
                + (f", {self.completeness_whole:.1%} of the whole surface " if self.completeness_whole is not None
                   else " ") +
                f"({self.visible_fraction:.0%} of the object is visible); {self.unobserved_area:.0%} of the mesh "
                f"fills unseen parts (RMS {self.unobserved_rms * 1e3:.2f} mm there; whole mesh "
                f"{self.rms_all * 1e3:.3f} mm)")


@dataclass(frozen=True, eq=False)
class ProcessResult:
    """What processing a session produced. Distances in metres, times in seconds."""

    folder: Path
    view_names: list[str]
    T_world_view: np.ndarray        # (n, 4, 4) registered poses, world = first view
    n_points: list[int]             # points per view after filtering
    edges: list[Edge]               # the registration's view pairs
    registration_rmse: float        # joint point-to-plane RMS of the final poses
    mesh: MeshFigures               # mesh.ply, the observed surface
    seconds: dict = field(default_factory=dict)   # wall time per stage
    accuracy: Accuracy | None = None   # against the truth when an evaluator was given
    laser: LaserSummary | None = None   # a laser scan: per laser its points, steps without a line, rejected rows
    watertight_mesh: MeshFigures | None = None   # the closed mesh (mesh_watertight.ply)
    view_errors: ViewErrors | None = None   # simulator: per view, decoding / cloud (inside, edge) / pose errors
    view_passes: list | None = None  # a multi-pass scan: each view's turntable pass (0, 1, ...)
    registration_note: str = ""     # a registration that failed and what was kept instead (the turntable's poses)
    options: dict | None = None     # the processing's options (ProcessOptions.to_dict: every field by name)

    @property
    def mesh_path(self) -> Path:
        return self.folder / MESH_FILE

    @property
    def mesh_watertight(self) -> bool:
        """A closed mesh was written (``mesh_watertight.ply``, or ``mesh.ply`` itself when closed)."""
        return bool((self.watertight_mesh or self.mesh).watertight)

    def to_dict(self) -> dict:
        """``summary.json``'s content (schema ``rangekit.summary/1``)."""
        return {"schema": SUMMARY_SCHEMA, "views": self.view_names, "n_points": self.n_points,
                "T_world_view": self.T_world_view.tolist(), "edges": [e.to_dict() for e in self.edges],
                "registration_rmse_m": None if np.isnan(self.registration_rmse) else self.registration_rmse,
                "mesh": self.mesh.to_dict(), "seconds": self.seconds,
                "accuracy": None if self.accuracy is None else self.accuracy.to_dict(),
                **({"laser": self.laser.to_dict()} if self.laser is not None else {}),
                **({"mesh_watertight": self.watertight_mesh.to_dict()} if self.watertight_mesh is not None else {}),
                **({"view_errors": self.view_errors.to_list()} if self.view_errors is not None else {}),
                **({"view_passes": self.view_passes} if self.view_passes is not None else {}),
                **({"registration_note": self.registration_note} if self.registration_note else {}),
                **({"options": self.options} if self.options is not None else {})}

    @classmethod
    def from_dict(cls, d: dict, folder: str | Path) -> "ProcessResult":
        """The result a ``summary.json`` (schema ``rangekit.summary/1``) of the session in ``folder`` holds.
        Raises FileFormatError naming the schema found when it is another."""
        from rangekit.errors import FileFormatError, shown

        if d.get("schema") != SUMMARY_SCHEMA:
            raise FileFormatError(f"{Path(folder) / SUMMARY_FILE}: schema: expected {SUMMARY_SCHEMA!r}, found "
                                  f"{shown(d.get('schema'))}")
        rmse = d.get("registration_rmse_m")
        acc, closed = d.get("accuracy"), d.get("mesh_watertight")
        laser, errors, options = d.get("laser"), d.get("view_errors"), d.get("options")
        return cls(Path(folder), list(d["views"]), np.array(d["T_world_view"], dtype=np.float64), list(d["n_points"]),
                   [Edge.from_dict(e) for e in d["edges"]], float("nan") if rmse is None else rmse,
                   MeshFigures.from_dict(d["mesh"]), dict(d.get("seconds", {})),
                   None if acc is None else Accuracy.from_dict(acc),
                   None if laser is None else LaserSummary.from_dict(laser),
                   None if closed is None else MeshFigures.from_dict(closed),
                   None if errors is None else ViewErrors.from_list(errors), d.get("view_passes"),
                   str(d.get("registration_note", "")), None if options is None else dict(options))

    def summary_lines(self) -> list[str]:
        """The end-of-run summary, one line per fact, for people (mm and degrees here only)."""
        acc = [e for e in self.edges if e.accepted]
        rot = [np.degrees(e.rotation_residual) for e in acc if e.rotation_residual is not None]
        tr = [e.translation_residual * 1e3 for e in acc if e.translation_residual is not None]
        m = self.mesh
        lines = [f"views: {len(self.view_names)}, points: {sum(self.n_points):,} "
                 f"({min(self.n_points):,} to {max(self.n_points):,} per view)"]
        if self.view_passes is not None:
            lines[-1] += f"; {max(self.view_passes) + 1} passes of {self.view_passes.count(0)} views"
        if self.laser is not None:
            lines.append("registration: none, each laser profile placed by its turntable angle; "
                         + "; ".join(laser.summary() for laser in self.laser.lasers))
        else:
            lines.append(f"registration: {len(acc)}/{len(self.edges)} pairs accepted, pair ICP RMSE median "
                         f"{np.median([e.rmse * 1e3 for e in acc]):.4f} mm, joint RMS {self.registration_rmse * 1e3:.4f} "
                         "mm" + (f"; synchronisation residual max {max(rot):.4f} deg, {max(tr):.4f} mm" if rot and tr
                                 else ""))
        if self.registration_note:
            lines.append(f"warning: {self.registration_note}")
        lines += [
                 f"mesh ({m.fusion}{', observed surface' if self.watertight_mesh else ''}): {m.vertices:,} "
                 f"vertices, {m.triangles:,} triangles, watertight {m.watertight}, area {m.area * 1e4:.1f} cm^2"
                 + (f", volume {m.volume * 1e6:.1f} cm^3" if m.volume is not None else "")]
        w = self.watertight_mesh
        if w:
            lines.append(f"closed mesh ({WATERTIGHT_FILE}): {w.vertices:,} vertices, watertight {w.watertight}"
                         + (f", volume {w.volume * 1e6:.1f} cm^3" if w.volume is not None else "")
                         + f"; {w.unobserved_vertices:,} vertices ({w.unobserved_area * 1e4:.1f} cm^2) no "
                           "view observed")
        lines.append("time: " + ", ".join(f"{k} {v:.1f} s" for k, v in self.seconds.items()))
        if self.accuracy:
            a = self.accuracy
            lines.append(f"accuracy against the true surface: RMS {a.rms * 1e3:.3f} mm "
                         f"({a.rms / a.diagonal:.3%} of the {a.diagonal * 1e3:.0f} mm diagonal), 95th "
                         f"percentile {a.p95 * 1e3:.3f} mm; completeness {a.completeness:.1%} of the visible "
                         f"surface within {a.tolerance * 1e3:g} mm"
                         + (f", {a.completeness_whole:.1%} of the whole surface" if a.completeness_whole
                            is not None else ""))
            if a.cloud_rms is not None:
                lines.append(f"cloud against the true surface: RMS {a.cloud_rms * 1e3:.3f} mm, 95th percentile "
                             f"{a.cloud_p95 * 1e3:.3f} mm over {a.n_cloud:,} points")
            if self.view_errors:
                lines.append(self.view_errors.summary_line())
            lines.append(f"  ({a.visible_fraction:.0%} of the object is visible within "
                         f"{round(math.degrees(a.max_incidence), 9):g} deg of incidence; {a.unobserved_area:.1%} of the "
                         f"mesh lies where no view can see, RMS {a.unobserved_rms * 1e3:.2f} mm there)")
            if a.watertight is not None:
                c = a.watertight
                lines.append(f"closed mesh against the true surface: RMS {c.rms * 1e3:.3f} mm, 95th percentile "
                             f"{c.p95 * 1e3:.3f} mm, completeness {c.completeness:.1%}; {c.unobserved_area:.0%} "
                             f"of it filled in where no view looked, RMS {c.unobserved_rms * 1e3:.2f} mm there")
        return lines

    def __repr__(self) -> str:
        t = ", ".join(f"{k} {v:.1f} s" for k, v in self.seconds.items())
        return (f"ProcessResult({len(self.n_points)} views, {sum(self.n_points)} points, mesh watertight "
                f"{self.mesh_watertight}; {t})")

