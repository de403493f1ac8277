"""The Sessions page's routes: ``GET /api/sessions`` (each session under ``--sessions``: state, figures, files),
``GET /api/sessions/NAME/files/FILE`` (its report.html, meshes, poses.json, summary.json), ``POST
/api/sessions/NAME/process`` ``{"fusion", "format", "report"}`` (``rangekit process`` again, as the scan job's
child: its events followed as a scan's), ``POST /api/sessions/NAME/export`` ``{"format"}`` (its meshes as obj,
stl or glb beside the PLY), ``GET /api/sessions/NAME/views/K/points`` (a decoded view's points, float32 x y z in
mm)."""

from __future__ import annotations

from rangekit.errors import RangekitError
from rangekit.ui.guard.fields import flag, text
from rangekit.ui.paths import confined
from rangekit.ui.routes.common import Ui, action, binary, reading

__all__ = ["routes"]


def routes(ui: Ui) -> list:
    from starlette.responses import FileResponse
    from starlette.routing import Route

    from rangekit.ui.sessions_list import session_file, sessions_listing
    from rangekit.ui.view_points import view_points

    scans, sessions = ui.scans, ui.sessions

    def process(request, f):
        return scans.process(request.path_params["name"], fusion=f["fusion"], mesh_format=f["format"],
                             report=f["report"])

    def export(request, f):
        from rangekit.app.process.fused_outputs import export_meshes

        folder = confined(sessions, request.path_params["name"])
        if scans.running and scans.name == folder.name:
            raise RangekitError(f"{folder.name} is being scanned or processed; export when it has finished")
        return {"files": export_meshes(folder, f["format"])}

    def file(request):
        path = session_file(sessions, request.path_params["name"], request.path_params["file"])
        return FileResponse(path, headers={"Cache-Control": "no-store"})

    return [
        Route("/api/sessions", reading(lambda r: sessions_listing(sessions))),
        Route("/api/sessions/{name}/files/{file}", reading(file, status_for_refusal=404)),
        Route("/api/sessions/{name}/process", action("process", {
            "fusion": text("poisson"), "format": text("ply"), "report": flag(True)}, process), methods=["POST"]),
        Route("/api/sessions/{name}/export", action("export", {"format": text("")}, export), methods=["POST"]),
        Route("/api/sessions/{name}/views/{index:int}/points", reading(lambda r: binary(view_points(
            confined(sessions, r.path_params["name"]), r.path_params["index"])))),
    ]
