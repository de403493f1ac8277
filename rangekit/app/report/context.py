"""What a report's panels show: one :class:`ReportContext` (the result, the session, the meshes and clouds in the
session world), with the pictures' sides and up direction."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Sequence

import numpy as np

if TYPE_CHECKING:
    from rangekit.formats.sessions.view_maps import ViewMaps
    from rangekit.app.report.view_rows import ViewRows
    from rangekit.formats.sessions.session import Session
    from rangekit.formats.sessions.summary import ProcessResult
    from rangekit.surface.cloud import PointCloud
    from rangekit.surface.mesh import TriangleMesh

__all__ = ["ReportContext", "views_agreement", "SIDES", "SIDE_NAMES", "table_up", "OBSERVED_COLOUR", "INVENTED_COLOUR"]


#: The sides the mesh is shown from: (azimuth, elevation) radians about the turntable axis, and their names.
SIDES = [(np.radians(a), np.radians(25.0)) for a in (0, 90, 180, 270)] + [(0.0, np.radians(80.0))]
SIDE_NAMES = ["front", "right", "back", "left", "top"]


def table_up(rig) -> np.ndarray:
    """The up direction of the pictures: the turntable axis (else the camera's -y)."""
    return rig.T_world_table[:3, 2] if rig.T_world_table is not None else np.array([0.0, -1.0, 0.0])


#: The report's colours of a closed mesh: surface some view observed, surface on the hull free-space carving
#: left (no view measured it, but views saw the space around it empty), and surface the fusion guessed.
OBSERVED_COLOUR = (0.35, 0.62, 0.85)
CARVED_COLOUR = (0.90, 0.62, 0.25)
INVENTED_COLOUR = (0.55, 0.55, 0.55)


@dataclass(frozen=True, eq=False)
class ReportContext:
    """Everything a panel may show, in the session world (the first view's frame).

    out : the session folder (report.html goes there); result, session : what processing made of it.
    mesh : the observed surface; watertight : the closed mesh with its ``observed`` flag; truth : the true
    surface (simulator) for the heat map.
    merged, clouds : the registered merged cloud, and each view's cloud in its own frame (coded light).
    rows : the per-view part made as the views were decoded (:class:`rangekit.app.report.view_rows.ViewRows`), or
    maps : the views' maps to make it from.
    profiles : a laser scan's profiles (:class:`rangekit.app.process.laser.LaserProfiles`).
    agreement : :func:`views_agreement` of ``mesh`` and the registered clouds when made already (processing
    makes it beside the closed mesh's evaluation); None: made here when a panel needs it.
    size : each picture's (width, height) in pixels; progress : ``progress(msg, done, total)``.
    """

    out: Path
    result: ProcessResult
    session: Session
    mesh: TriangleMesh
    watertight: TriangleMesh | None = None
    truth: TriangleMesh | None = None
    merged: PointCloud | None = None
    clouds: Sequence[PointCloud] | None = None
    rows: ViewRows | None = None
    maps: Sequence[ViewMaps] | None = None
    profiles: object | None = None
    agreement: tuple | None = None
    size: tuple[int, int] = (230, 230)
    progress: Callable | None = None

    @cached_property
    def up(self) -> np.ndarray:
        return table_up(self.session.rig)

    @cached_property
    def quality(self) -> tuple:
        """The views' agreement on the mesh (:func:`rangekit.app.report.quality.mesh_quality`): its sample
        vertices and quality map, computed once for the panels that show it."""
        from rangekit.progress import call_progress

        call_progress(self.progress, "report: views' agreement and coverage")
        if self.agreement is not None:
            return self.agreement
        return views_agreement(self.mesh, self.result.T_world_view, self.clouds)


def views_agreement(mesh: TriangleMesh, T_world_view: np.ndarray, clouds: Sequence[PointCloud]) -> tuple:
    """:func:`rangekit.app.report.quality.mesh_quality` of ``mesh`` (the observed surface, session world) and
    the views' ``clouds`` (each in its own frame) placed by ``T_world_view`` (n, 4, 4): ``(vertices used,
    QualityMap)``, the report's views' agreement and coverage."""
    from rangekit.app.report.quality import mesh_quality
    from rangekit.geometry import apply_T

    clouds_world = [apply_T(T, c.points) for T, c in zip(T_world_view, clouds)]
    return mesh_quality(mesh.vertices, mesh.triangles, clouds_world, normal_sums=mesh.normal_sums)
