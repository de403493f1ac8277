"""A fusion's two meshes as processing keeps them (coded light and laser sessions alike):

    mesh.ply              the observed surface only (open): what some view's points support
    mesh_watertight.ply   the same surface closed, with the PLY vertex property ``observed`` (uchar, 0 where
                          no view's points support the vertex: the closing, the balloon, a web across a gap)

:func:`save_fused` writes both and returns their ``summary.json`` entries (:func:`save_one` one of them);
:func:`evaluate_fused` measures both against the truth (the summary's accuracy is the observed mesh's, the
closed one's figures are kept under ``accuracy["watertight"]``); in two halves, :func:`evaluate_observed` then
:func:`with_closed`, the observed mesh is measured while the closed one is made. Given another ``mesh_format``
(``--format obj|stl|glb``: what MeshLab, Blender or a slicer opens; only PLY keeps ``observed``) each mesh is
also written in it beside its PLY, from the same mesh in memory.
"""

from __future__ import annotations

from pathlib import Path
from typing import Callable

from rangekit.surface.mesh import TriangleMesh
from rangekit.surface.observed import FusedMeshes

__all__ = ["MESH_FILE", "WATERTIGHT_FILE", "WATERTIGHT_FIGURES", "MESH_EXPORT_FORMATS", "mesh_info", "save_fused",
           "save_one", "evaluate_fused", "evaluate_observed", "with_closed"]

MESH_FILE = "mesh.ply"
WATERTIGHT_FILE = "mesh_watertight.ply"
#: ``--format`` of scan and process: the mesh files' format (PLY always written; the others beside it).
MESH_EXPORT_FORMATS = ("ply", "obj", "stl", "glb")
#: The closed mesh's accuracy figures kept in the summary (``accuracy["watertight"]``).
WATERTIGHT_FIGURES = ("rms", "p95", "max", "completeness", "unobserved_area", "unobserved_rms", "rms_all")


def mesh_info(mesh: TriangleMesh, fusion: str, file: str) -> dict:
    """A mesh's ``summary.json`` entry: file, vertices, triangles, watertight, area_m2, volume_m3 (closed
    meshes only), fusion; with an ``observed`` flag also unobserved_vertices and unobserved_area_m2."""
    info = {"file": file, "vertices": len(mesh.vertices), "triangles": len(mesh.triangles),
            "watertight": bool(mesh.is_watertight), "area_m2": float(mesh.area),
            "volume_m3": float(abs(mesh.volume)) if mesh.is_watertight else None, "fusion": fusion}
    if mesh.observed is not None:
        info["unobserved_vertices"] = int((~mesh.observed).sum())
        info["unobserved_area_m2"] = FusedMeshes(mesh, mesh).unobserved_area
    return info


def save_fused(out: Path, fused: FusedMeshes, fusion: str, mesh_format: str = "ply") -> tuple[dict, dict]:
    """Write ``out/mesh.ply`` (observed) and ``out/mesh_watertight.ply`` (closed, flagged), atomically (and each
    as ``mesh_format`` beside it); return their summary entries (:func:`mesh_info`)."""
    return (save_one(out, fused.observed, fusion, MESH_FILE, mesh_format),
            save_one(out, fused.watertight, fusion, WATERTIGHT_FILE, mesh_format))


def save_one(out: Path, mesh: TriangleMesh, fusion: str, file: str, mesh_format: str = "ply") -> dict:
    """Write one of the two (``file``: :data:`MESH_FILE` or :data:`WATERTIGHT_FILE`) atomically, and as
    ``STEM.mesh_format`` beside it when that is not ``"ply"``; its summary entry (:func:`mesh_info`)."""
    from rangekit.formats.meshes import save_mesh

    save_mesh(out / file, mesh)
    if mesh_format != "ply":
        save_mesh(out / f"{Path(file).stem}.{mesh_format}", mesh)
    return mesh_info(mesh, fusion, file)


def evaluate_fused(evaluate: Callable, fused: FusedMeshes, angles, *, views: dict | None = None,
                   **options) -> tuple[dict, object, list | None]:
    """``(accuracy dict, truth, view errors)``: ``evaluate(mesh, angles, **options)`` on the observed mesh
    (with ``views``, the per-view breakdown, once), with the watertight mesh's :data:`WATERTIGHT_FIGURES`
    under ``"watertight"``."""
    evaluation = evaluate_observed(evaluate, fused.observed, angles, views=views, **options)
    return with_closed(evaluate, evaluation, fused.watertight, angles, **options)


def evaluate_observed(evaluate: Callable, mesh: TriangleMesh, angles, *, views: dict | None = None, **options):
    """The first half of :func:`evaluate_fused`: the evaluator's answer for the observed mesh alone (the
    closed one can still be in the making)."""
    return evaluate(mesh, angles, **options, **({"views": views} if views is not None else {}))


def with_closed(evaluate: Callable, evaluation, watertight: TriangleMesh, angles,
                **options) -> tuple[dict, object, list | None]:
    """The second half of :func:`evaluate_fused`: ``evaluation`` (of the observed mesh) with the closed
    mesh's figures under ``"watertight"``, as :func:`evaluate_fused` returns it."""
    accuracy = evaluation.accuracy.to_dict()
    closed = evaluate(watertight, angles, **options).accuracy.to_dict()
    accuracy["watertight"] = {k: closed[k] for k in WATERTIGHT_FIGURES}
    return accuracy, evaluation.truth, evaluation.view_errors
