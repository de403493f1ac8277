"""The Registration page's routes: ``GET /api/register`` (the registration: its pairs' residuals), ``GET
/api/register/clouds`` (the cloud files under ``--sessions``), ``POST /api/register/start`` ``{"files",
"neighbours"}``, ``POST /api/register/save`` ``{"name"}``, ``GET /api/register/points/K`` (cloud K placed by its
registered pose, float32 mm)."""

from __future__ import annotations

from rangekit.ui.guard.fields import text, texts
from rangekit.ui.guard.names import check_folder_name
from rangekit.ui.routes.common import Ui, action, binary, given, reading

__all__ = ["routes"]


def routes(ui: Ui) -> list:
    from starlette.routing import Route

    from rangekit.ui.jobs.register import list_clouds

    registration = ui.registration
    return [
        Route("/api/register", reading(lambda r: registration.snapshot())),
        Route("/api/register/clouds", reading(lambda r: {"clouds": list_clouds(ui.sessions)})),
        Route("/api/register/points/{index:int}", reading(lambda r: binary(registration.points(
            r.path_params["index"])))),
        Route("/api/register/start", action("register", {"files": texts(2000), "neighbours": given(None)},
                                            lambda r, f: registration.start(f["files"], f["neighbours"])),
              methods=["POST"]),
        Route("/api/register/save", action("register save", {"name": text()},
                                           lambda r, f: registration.save(check_folder_name(f["name"]))),
              methods=["POST"]),
    ]
