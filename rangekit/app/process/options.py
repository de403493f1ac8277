"""How a session is processed: one frozen, validated value (``rangekit process`` and the end of ``rangekit scan``
map their flags onto it; ``ScanOptions.processing`` holds one). Each field's flag and range are its metadata
(:mod:`rangekit._runtime.option_fields`); a bad value is an :class:`~rangekit.errors.OptionError` naming the field
(``{poisson_depth}``), which the command line shows as its flag (:data:`PROCESS_FLAGS`)."""

from __future__ import annotations

from dataclasses import asdict, dataclass

from rangekit._runtime.arguments import check_bool, check_choice, check_number
from rangekit._runtime.option_fields import check_ranges, flags, option
from rangekit.coded.motion.check import MAX_MOTION_SHARE
from rangekit.errors import OptionError

__all__ = ["FUSION_METHODS", "TRIANGULATION_METHODS", "POISSON_DEFAULTS", "POISSON_POINTS", "ProcessOptions",
           "PROCESS_FLAGS"]

#: ``fusion``: screened Poisson on the merged oriented cloud (``rangekit process``'s default), the truncated
#: signed distance volume of the registered depth maps (dense, the batch's), or ``blocks``: the sparse TSDF volume a
#: scan streams its views into (0.4 mm voxels, each view's depth carried 4 px past its rim), its observed cut
#: projected onto the points' planes (issue 51: ``rangekit scan``'s default, no Poisson after the last frame;
#: :func:`rangekit.app.process.fuse.blocks_surface`).
FUSION_METHODS = ("poisson", "tsdf", "blocks")
#: ``method``: how a coded-light pixel is triangulated (:func:`rangekit.coded.triangulate.triangulate`).
TRIANGULATION_METHODS = ("auto", "ray-plane", "ray-ray")
#: Poisson's input of a coded-light scan: every k-th merged point, k the smallest that leaves at most this many.
#: With the octree at depth 8 more points per cell average more noise out: on the default 12-view scan (2.02M
#: points) 674k points measure 0.012 mm RMS against the truth where 404k measured 0.017 mm; every point (2.02M)
#: measured 0.008 mm but the observed cut, spaced by these points, then kept less (completeness 99.4% against
#: 99.6%). docs/benchmarks.md, issue 36.
POISSON_POINTS = 700_000
#: ``poisson_depth`` and ``poisson_points`` left None: each scan method's own (coded light: depth 8 and
#: :data:`POISSON_POINTS`, issue 36; a laser scan: depth 9 and 400k points, as it was measured when it was made,
#: docs/benchmarks.md issue 49).
POISSON_DEFAULTS = {"coded": (8, POISSON_POINTS), "laser": (9, 400_000)}


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
    poisson_depth : the screened Poisson octree's depth (1-12; None: the scan method's, :data:`POISSON_DEFAULTS`,
        8 for coded light and 9 for a laser scan): its finest cell is 1.1 x the merged cloud's
        largest side / 2**depth (0.75 mm on the default 180 mm object at 8). Each step up quadruples the mesh and
        about triples the fusion's time. 8 measures the default scan as well as 9 did (0.012 mm RMS on 674k points
        against 0.017 mm at 9 on 404k) in a third of the time; fine parts of a small object (the thin object's
        1-2 mm fins) measure better at 9 (0.066 mm RMS against 0.069). docs/benchmarks.md, issue 36.
    max_motion : a view of a Gray-code, XOR or hybrid capture in which more than this share of the decoded pixels
        moved during the capture is refused (MotionError naming the view and the frames; ``rangekit scan`` takes
        such a view again): :func:`rangekit.coded.motion.detect_motion`, which changes no pixel of a still view.
        None: not checked.
    poisson_points : the most merged points Poisson is given (every k-th point, k the smallest that leaves at most
        this many; 10,000-100,000,000); None: the scan method's (:data:`POISSON_DEFAULTS`).
    """

    fusion: str = option("poisson", "--fusion")
    method: str = option("auto")
    table_margin: float = option(0.002, lo=0, hi=1, hi_open=True, unit="metres")
    report: bool = option(True, "--no-report")
    truth: bool = option(True)
    mesh_format: str = option("ply", "--format")
    poisson_depth: int | None = option(None, "--poisson-depth", lo=1, hi=12, integer=True)
    max_motion: float | None = option(MAX_MOTION_SHARE, "--max-motion", lo=0, hi=1, unit="a share",
                                          optional=True)
    poisson_points: int | None = option(None, lo=10_000, hi=100_000_000, integer=True)

    def __post_init__(self) -> None:
        from rangekit.app.process.fused_outputs import MESH_EXPORT_FORMATS

        check_choice("{fusion}", self.fusion, FUSION_METHODS, error=OptionError)
        check_choice("{method}", self.method, TRIANGULATION_METHODS, error=OptionError)
        check_choice("{mesh_format}", self.mesh_format, MESH_EXPORT_FORMATS, error=OptionError)
        check_ranges(self, OptionError)
        for name in ("report", "truth"):
            check_bool(f"{{{name}}}", getattr(self, name), error=OptionError)

    def poisson(self, laser: bool) -> tuple[int, int]:
        """``(depth, points)`` of the screened Poisson fusion of a coded-light (``laser`` False) or laser scan: the
        given ones, else the method's (:data:`POISSON_DEFAULTS`)."""
        depth, points = POISSON_DEFAULTS["laser" if laser else "coded"]
        return (depth if self.poisson_depth is None else self.poisson_depth,
                points if self.poisson_points is None else self.poisson_points)

    def to_dict(self) -> dict:
        """The options as summary.json records them (``options``): every field by name, as given (None: the
        method's default)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> "ProcessOptions":
        """The options a summary.json's ``options`` records (fields it does not name take their defaults)."""
        names = set(cls.__dataclass_fields__)
        return cls(**{k: v for k, v in d.items() if k in names})


#: Each field's ``rangekit process`` (and ``rangekit scan``) flag, for :meth:`rangekit.errors.OptionError.named`
#: (``report``'s is its negation).
PROCESS_FLAGS = flags(ProcessOptions)
