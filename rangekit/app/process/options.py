"""How a session is processed: one frozen, validated value (``rangekit process`` and the end of ``rangekit scan``
map their flags onto it)."""

from __future__ import annotations

from dataclasses import dataclass

from rangekit._runtime.arguments import check_bool, check_choice, check_number
from rangekit.coded.motion.check import MAX_MOTION_SHARE
from rangekit.errors import ConfigError

__all__ = ["FUSION_METHODS", "TRIANGULATION_METHODS", "ProcessOptions"]

#: ``fusion``: screened Poisson on the merged oriented cloud (the default, the more accurate) or the truncated
#: signed distance volume of the registered depth maps.
FUSION_METHODS = ("poisson", "tsdf")
#: ``method``: how a coded-light pixel is triangulated (:func:`rangekit.coded.triangulate.triangulate`).
TRIANGULATION_METHODS = ("auto", "ray-plane", "ray-ray")


@dataclass(frozen=True)
class ProcessOptions:
    """What processing does with a session.

    fusion : one of :data:`FUSION_METHODS`.
    method : triangulation, one of :data:`TRIANGULATION_METHODS`.
    table_margin : metres; points within this height of the turntable top (or below it) are dropped, so the
        table does not become part of the object.
    report : write ``report.html``.
    mesh_format : the two meshes' files: ``"ply"`` (mesh.ply and mesh_watertight.ply, with vertex normals and
        the ``observed`` flag) or ``"obj"``, ``"stl"``, ``"glb"`` written beside them from the same meshes
        (:data:`rangekit.app.process.fused_outputs.MESH_EXPORT_FORMATS`).
    truth : measure against the simulator's truth when the session is simulated (never on hardware).
    poisson_depth : the screened Poisson octree's depth (1-12): its finest cell is 1.1 x the merged cloud's
        largest side / 2**depth (0.75 mm on the default 180 mm object at 8). Each step up quadruples the mesh and
        about triples the fusion's time. 8 measures the default scan as well as 9 did (0.012 mm RMS on 674k points
        against 0.017 mm at 9 on 404k) in a third of the time; fine parts of a small object (the thin object's
        1-2 mm fins) measure better at 9 (0.066 mm RMS against 0.069). docs/benchmarks.md, issue 36.
    max_motion : a view of a Gray-code, XOR or hybrid capture in which more than this share of the decoded pixels
        moved during the capture is refused (MotionError naming the view and the frames; ``rangekit scan`` takes
        such a view again): :func:`rangekit.coded.motion.detect_motion`, which changes no pixel of a still view.
        None: not checked.
    """

    fusion: str = "poisson"
    method: str = "auto"
    table_margin: float = 0.002
    report: bool = True
    truth: bool = True
    mesh_format: str = "ply"
    poisson_depth: int = 8
    max_motion: float | None = MAX_MOTION_SHARE

    def __post_init__(self) -> None:
        from rangekit.app.process.fused_outputs import MESH_EXPORT_FORMATS

        check_choice("fusion", self.fusion, FUSION_METHODS, error=ConfigError)
        check_choice("method", self.method, TRIANGULATION_METHODS, error=ConfigError)
        check_number("table_margin", self.table_margin, lo=0, hi=1, hi_open=True, unit="metres", error=ConfigError)
        check_choice("mesh_format", self.mesh_format, MESH_EXPORT_FORMATS, error=ConfigError)
        check_number("poisson_depth", self.poisson_depth, lo=1, hi=12, integer=True, error=ConfigError)
        check_number("max_motion", self.max_motion, lo=0, hi=1, unit="a share", optional=True, error=ConfigError)
        for name in ("report", "truth"):
            check_bool(name, getattr(self, name), error=ConfigError)
