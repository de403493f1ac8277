"""A fusion's two meshes as processing keeps them (coded light and laser sessions alike):

    mesh.ply              the observed surface only (open): what some view's points support
    mesh_watertight.ply   the same surface closed, with the PLY vertex property ``observed`` (uchar, 0 where
                          no view's points support the vertex: the closing, the balloon, a web across a gap)
                          and ``carved`` (uchar, 1 where such a vertex lies on the hull the views' free space
                          left, rangekit.surface.carve; both 0: guessed)

:func:`save_fused` writes both and returns their ``summary.json`` entries (:func:`save_one` one of them);
:func:`evaluate_fused` measures both against the truth (the summary's accuracy is the observed mesh's, the
closed one's figures are its ``watertight``); in two halves, :func:`evaluate_observed` then
:func:`with_closed`, the observed mesh is measured while the closed one is made. Given another ``mesh_format``
(``--format obj|stl|glb``: what MeshLab, Blender or a slicer opens; only PLY keeps ``observed``) each mesh is
also written in it beside its PLY, from the same mesh in memory.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from rangekit.formats.meshes import MESH_FORMATS
from rangekit.formats.sessions.summary import Accuracy, ClosedAccuracy, MeshFigures
from rangekit.surface.mesh import TriangleMesh
from rangekit.surface.observed import FusedMeshes
from rangekit.formats.sessions.files import MESH_FILE, WATERTIGHT_FILE

__all__ = ["MESH_EXPORT_FORMATS", "export_meshes", "mesh_info", "save_fused",
           "save_one", "evaluate_fused", "evaluate_observed", "with_closed"]

#: ``--format`` of scan and process: the mesh files' format (PLY always written; the others beside it): the
#: mesh writers of rangekit.formats.meshes.MESH_FORMATS, the one list.
MESH_EXPORT_FORMATS = tuple(suffix[1:] for suffix in MESH_FORMATS)


def mesh_info(mesh: TriangleMesh, fusion: str, file: str) -> MeshFigures:
    """A mesh's figures (``summary.json``'s entry): size, watertight, area (m^2), volume (m^3, closed meshes
    only), fusion; with an ``observed`` flag also the unobserved vertices and area."""
    unobserved = None if mesh.observed is None else (int((~mesh.observed).sum()),
                                                     FusedMeshes(mesh, mesh).unobserved_area)
    return MeshFigures(file, len(mesh.vertices), len(mesh.triangles), bool(mesh.is_watertight), float(mesh.area),
                       float(abs(mesh.volume)) if mesh.is_watertight else None, fusion,
                       *(unobserved or (None, None)))


def save_fused(out: Path, fused: FusedMeshes, fusion: str, mesh_format: str = "ply") -> tuple[MeshFigures, MeshFigures]:
    """Write ``out/mesh.ply`` (observed) and ``out/mesh_watertight.ply`` (closed, flagged), atomically (and each
    as ``mesh_format`` beside it); return their summary entries (:func:`mesh_info`)."""
    return (save_one(out, fused.observed, fusion, MESH_FILE, mesh_format),
            save_one(out, fused.watertight, fusion, WATERTIGHT_FILE, mesh_format))


def save_one(out: Path, mesh: TriangleMesh, fusion: str, file: str, mesh_format: str = "ply") -> MeshFigures:
    """Write one of the two (``file``: :data:`MESH_FILE` or :data:`WATERTIGHT_FILE`) atomically, and as
    ``STEM.mesh_format`` beside it when that is not ``"ply"``; its summary entry (:func:`mesh_info`)."""
    from rangekit.formats.meshes import save_mesh

    save_mesh(out / file, mesh)
    if mesh_format != "ply":
        save_mesh(out / f"{Path(file).stem}.{mesh_format}", mesh)
    return mesh_info(mesh, fusion, file)


def evaluate_fused(evaluate: Callable, fused: FusedMeshes, angles, *, views: dict | None = None,
                   **options) -> tuple[Accuracy, object, list | None]:
    """``(accuracy, truth, view errors)``: ``evaluate(mesh, angles, **options)`` on the observed mesh
    (with ``views``, the per-view breakdown, once), with the watertight mesh's figures as its ``watertight``."""
    evaluation = evaluate_observed(evaluate, fused.observed, angles, views=views, **options)
    return with_closed(evaluate, evaluation, fused.watertight, angles, **options)


def evaluate_observed(evaluate: Callable, mesh: TriangleMesh, angles, *, views: dict | None = None, **options):
    """The first half of :func:`evaluate_fused`: the evaluator's answer for the observed mesh alone (the
    closed one can still be in the making)."""
    return evaluate(mesh, angles, **options, **({"views": views} if views is not None else {}))


def with_closed(evaluate: Callable, evaluation, watertight: TriangleMesh, angles,
                **options) -> tuple[Accuracy, object, list | None]:
    """The second half of :func:`evaluate_fused`: ``evaluation`` (of the observed mesh) with the closed
    mesh's figures as its ``watertight``, as :func:`evaluate_fused` returns it."""
    from dataclasses import fields, replace

    closed = evaluate(watertight, angles, **options).accuracy
    figures = ClosedAccuracy(**{f.name: getattr(closed, f.name) for f in fields(ClosedAccuracy)})
    return replace(evaluation.accuracy, watertight=figures), evaluation.truth, evaluation.view_errors


def export_meshes(folder: Path, mesh_format: str) -> list[str]:
    """A processed session's two meshes written again as ``STEM.mesh_format`` beside their PLY (what ``--format``
    would have written, from the PLY as saved; the web app's export); the files' names."""
    from rangekit.errors import UsageError
    from rangekit.formats.meshes import load_mesh, save_mesh

    if mesh_format not in MESH_EXPORT_FORMATS:
        raise UsageError(f"format {mesh_format!r}: expected one of {', '.join(MESH_EXPORT_FORMATS)}")
    written = []
    for file in (MESH_FILE, WATERTIGHT_FILE):
        if not (Path(folder) / file).is_file():
            raise UsageError(f"{Path(folder).name}/{file}: not there; process the session first")
        name = f"{Path(file).stem}.{mesh_format}"
        if mesh_format != "ply":
            save_mesh(Path(folder) / name, load_mesh(Path(folder) / file))
        written.append(name)
    return written
