"""What processing a session produced (``summary.json``, schema ``rangekit.summary/1``), as one value.

:func:`rangekit.app.process.process.process_session` writes it into the session folder last, after the mesh,
poses and merged cloud, so a folder holding ``summary.json`` holds all of them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["SUMMARY_SCHEMA", "ProcessResult"]

SUMMARY_SCHEMA = "rangekit.summary/1"


@dataclass(frozen=True, eq=False)
class ProcessResult:
    """What processing a session produced. Distances in metres, times in seconds."""

    folder: Path
    view_names: list[str]
    T_world_view: np.ndarray        # (n, 4, 4) registered poses, world = first view
    n_points: list[int]             # points per view after filtering
    edges: list[dict]               # view graph: i, j, rmse, overlap, accepted, rotation/translation residual
    registration_rmse: float        # joint point-to-plane RMS of the final poses
    mesh: dict                      # vertices, triangles, watertight, area_m2, volume_m3, fusion
    seconds: dict = field(default_factory=dict)   # wall time per stage
    accuracy: dict | None = None    # against the truth when an evaluator was given (the simulator's Accuracy)
    laser: dict | None = None       # a laser scan: per laser its points, steps without a line, rejected rows
    watertight_mesh: dict | None = None   # the closed mesh (mesh_watertight.ply), as ``mesh`` plus unobserved_*
    view_errors: list | None = None  # simulator: per view, decoding / cloud (inside, edge) / registration errors
    view_passes: list | None = None  # a multi-pass scan: each view's turntable pass (0, 1, ...)

    @property
    def mesh_path(self) -> Path:
        return self.folder / "mesh.ply"

    @property
    def mesh_watertight(self) -> bool:
        """A closed mesh was written (``mesh_watertight.ply``, or ``mesh.ply`` itself when closed)."""
        return bool((self.watertight_mesh or self.mesh)["watertight"])

    def to_dict(self) -> dict:
        return {"schema": SUMMARY_SCHEMA, "views": self.view_names, "n_points": self.n_points,
                "T_world_view": self.T_world_view.tolist(), "edges": self.edges,
                "registration_rmse_m": None if np.isnan(self.registration_rmse) else self.registration_rmse, "mesh": self.mesh, "seconds": self.seconds,
                "accuracy": self.accuracy, **({"laser": self.laser} if self.laser is not None else {}),
                **({"mesh_watertight": self.watertight_mesh} if self.watertight_mesh is not None else {}),
                **({"view_errors": self.view_errors} if self.view_errors is not None else {}),
                **({"view_passes": self.view_passes} if self.view_passes is not None else {})}

    def summary_lines(self) -> list[str]:
        """The end-of-run summary, one line per fact, for people."""
        acc = [e for e in self.edges if e["accepted"]]
        rot = [e["rotation_residual_deg"] for e in acc if e.get("rotation_residual_deg") is not None]
        tr = [e["translation_residual_mm"] for e in acc if e.get("translation_residual_mm") is not None]
        m = self.mesh
        lines = [f"views: {len(self.view_names)}, points: {sum(self.n_points):,} "
                 f"({min(self.n_points):,} to {max(self.n_points):,} per view)"]
        if self.view_passes is not None:
            lines[-1] += f"; {max(self.view_passes) + 1} passes of {self.view_passes.count(0)} views"
        if self.laser is not None:
            lines.append("registration: none, each laser profile placed by its turntable angle; " + "; ".join(
                f"{d['name']}: {d['points']:,} points, no line in {d['steps_without_line']} step(s)"
                + (f", {d['rejected_rows'].get('saturated', 0):,} saturated rows" if d["rejected_rows"].get("saturated")
                   else "") for d in self.laser["lasers"]))
        else:
            lines.append(f"registration: {len(acc)}/{len(self.edges)} pairs accepted, pair ICP RMSE median "
                         f"{np.median([e['rmse_mm'] for e in acc]):.4f} mm, joint RMS {self.registration_rmse * 1e3:.4f} "
                         "mm" + (f"; synchronisation residual max {max(rot):.4f} deg, {max(tr):.4f} mm" if rot and tr
                                 else ""))
        lines += [
                 f"mesh ({m['fusion']}{', observed surface' if self.watertight_mesh else ''}): {m['vertices']:,} "
                 f"vertices, {m['triangles']:,} triangles, watertight {m['watertight']}, area {m['area_m2'] * 1e4:.1f} cm^2"
                 + (f", volume {m['volume_m3'] * 1e6:.1f} cm^3" if m["volume_m3"] is not None else "")]
        w = self.watertight_mesh
        if w:
            lines.append(f"closed mesh (mesh_watertight.ply): {w['vertices']:,} vertices, watertight {w['watertight']}"
                         + (f", volume {w['volume_m3'] * 1e6:.1f} cm^3" if w["volume_m3"] is not None else "")
                         + f"; {w['unobserved_vertices']:,} vertices ({w['unobserved_area_m2'] * 1e4:.1f} cm^2) no "
                           "view observed")
        lines.append("time: " + ", ".join(f"{k} {v:.1f} s" for k, v in self.seconds.items()))
        if self.accuracy:
            a = self.accuracy
            lines.append(f"accuracy against the true surface: RMS {a['rms'] * 1e3:.3f} mm "
                         f"({a['rms'] / a['diagonal']:.3%} of the {a['diagonal'] * 1e3:.0f} mm diagonal), 95th "
                         f"percentile {a['p95'] * 1e3:.3f} mm; completeness {a['completeness']:.1%} of the visible "
                         f"surface within {a['tolerance'] * 1e3:g} mm"
                         + (f", {a['completeness_whole']:.1%} of the whole surface" if a.get("completeness_whole")
                            is not None else ""))
            if a.get("cloud_rms") is not None:
                lines.append(f"cloud against the true surface: RMS {a['cloud_rms'] * 1e3:.3f} mm, 95th percentile "
                             f"{a['cloud_p95'] * 1e3:.3f} mm over {a['n_cloud']:,} points")
            if self.view_errors:
                lines.append(_view_errors_line(self.view_errors))
            lines.append(f"  ({a['visible_fraction']:.0%} of the object is visible within "
                         f"{a['max_incidence_deg']:g} deg of incidence; {a['unobserved_area']:.1%} of the "
                         f"mesh lies where no view can see, RMS {a['unobserved_rms'] * 1e3:.2f} mm there)")
            if a.get("watertight"):
                c = a["watertight"]
                lines.append(f"closed mesh against the true surface: RMS {c['rms'] * 1e3:.3f} mm, 95th percentile "
                             f"{c['p95'] * 1e3:.3f} mm, completeness {c['completeness']:.1%}; {c['unobserved_area']:.0%} "
                             f"of it filled in where no view looked, RMS {c['unobserved_rms'] * 1e3:.2f} mm there")
        return lines

    def __repr__(self) -> str:
        t = ", ".join(f"{k} {v:.1f} s" for k, v in self.seconds.items())
        return (f"ProcessResult({len(self.n_points)} views, {sum(self.n_points)} points, mesh watertight "
                f"{self.mesh_watertight}; {t})")


def _view_errors_line(views: list[dict]) -> str:
    """One summary line of the per-view breakdown: the ranges over the views."""
    def span(values, fmt):
        values = [v for v in values if v is not None]
        return f"{min(values):{fmt}}-{max(values):{fmt}}" if values else "n/a"

    cloud = [v["cloud"] for v in views]
    reg = [v["registration"] for v in views]
    dec = [v["decoding"]["rms_px"] for v in views if v.get("decoding")]
    return (f"per view against the truth: cloud RMS {span([c['rms_mm'] for c in cloud], '.4f')} mm (depth-edge "
            f"points {span([100 * c['edge_share'] for c in cloud], '.0f')}% of the squared error), decoding RMS "
            f"{span(dec, '.3f')} px, registration within {max(r['rotation_deg'] for r in reg):.4f} deg and "
            f"{max(r['translation_mm'] for r in reg):.4f} mm of the true turntable poses")
