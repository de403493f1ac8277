"""The Check page's routes: ``GET /api/check`` (the latest check: idle, running with its progress, done, failed),
``POST /api/check/run``, ``POST /api/check/apply`` (its suggested rig-file changes written), ``GET
/api/check/figure.png``."""

from __future__ import annotations

from rangekit.ui.routes.common import Ui, action, png, reading

__all__ = ["routes"]


def routes(ui: Ui) -> list:
    from starlette.routing import Route

    check = ui.check
    return [
        Route("/api/check", reading(lambda r: check.snapshot())),
        Route("/api/check/run", action("check", {}, lambda r, f: check.start()), methods=["POST"]),
        Route("/api/check/apply", action("check apply", {}, lambda r, f: {"rig": check.apply()}), methods=["POST"]),
        Route("/api/check/figure.png", reading(lambda r: png(check.figure_png, "no check picture yet: run the check"))),
    ]
