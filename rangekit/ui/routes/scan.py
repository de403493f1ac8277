"""The Scan page's routes: ``GET /api/options`` (the scan's and the processing's ranges and defaults, from their
dataclasses: :func:`rangekit.ui.scan_options.option_limits`), ``GET /api/scan`` (the scan job as its events tell it: running, its views, files, the
child's last lines), ``POST /api/scan/start`` ``{"name", "views"}`` or ``{"name", "resume": true}``, ``POST
/api/scan/stop``, ``POST /api/scan/pause`` ``{"paused"}``. The page itself follows the job on ``/ws/events``
(:mod:`rangekit.ui.routes.events`)."""

from __future__ import annotations

from rangekit.ui.guard.fields import flag, text
from rangekit.ui.guard.names import check_folder_name
from rangekit.ui.routes.common import Ui, action, given, reading
from rangekit.ui.scan_options import option_limits

__all__ = ["routes"]


def routes(ui: Ui) -> list:
    from starlette.routing import Route

    scans = ui.scans
    return [
        Route("/api/scan", reading(lambda r: scans.snapshot())),
        Route("/api/options", reading(lambda r: option_limits())),
        Route("/api/scan/start", action("scan", {"name": text(), "views": given(option_limits()["scan"]["views"]["default"]),
                                                 "resume": flag(False)},
                                        lambda r, f: scans.start(check_folder_name(f["name"]), f["views"],
                                                                 resume=f["resume"])), methods=["POST"]),
        Route("/api/scan/stop", action("scan stop", {}, lambda r, f: scans.stop()), methods=["POST"]),
        Route("/api/scan/pause", action("scan pause", {"paused": flag(True)}, lambda r, f: scans.pause(f["paused"])),
              methods=["POST"]),
    ]
