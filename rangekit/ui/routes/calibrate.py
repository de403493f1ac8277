"""The Calibrate page's routes: ``GET /api/calibrate`` (the wizard: its state, poses, hint, result), ``POST
/api/calibrate/ACTION`` (start ``{"poses", "seed"}``, capture, keep, retake, next, drag ``{"dx", "dy"}``, cancel),
``GET /api/calibrate/picture/coverage.png`` and ``tilts.png``; ``GET /api/calibrate-recorded``, ``POST
/api/calibrate-recorded/start`` ``{"captures", "pattern", "projector", "out", "cols", "rows", "square_mm",
"replace"}`` (recorded pose folders under ``--sessions``)."""

from __future__ import annotations

from rangekit.ui.guard.fields import flag, text
from rangekit.ui.routes.common import Ui, action, given, json_response, png, reading

__all__ = ["ACTIONS", "routes"]

#: The wizard's actions and their fields.
ACTIONS = {"start": {"poses": given(12), "seed": given(0)}, "drag": {"dx": given(), "dy": given()},
           **{a: {} for a in ("capture", "keep", "retake", "next", "cancel")}}


def routes(ui: Ui) -> list:
    from starlette.routing import Route

    calibration, recorded = ui.calibration, ui.recorded

    def act(name: str):
        def run(request, f):
            if name == "start":
                return calibration.start(f["poses"], f["seed"])
            if name == "drag":
                return calibration.drag(f["dx"], f["dy"])
            return {"capture": calibration.capture, "keep": lambda: calibration.decide(True),
                    "retake": lambda: calibration.decide(False), "next": calibration.next_pose,
                    "cancel": calibration.cancel}[name]()
        return action(f"calibrate {name}", ACTIONS[name], run)

    endpoints = {name: act(name) for name in ACTIONS}

    async def wizard(request):
        name = request.path_params["action"]
        if name not in endpoints:
            return json_response({"error": f"calibrate: {name[:40]}: unknown; expected start, capture, keep, "
                                           "retake, next, drag or cancel"}, 404)
        return await endpoints[name](request)

    def recorded_start(request, f):
        return recorded.start(f["captures"], f["pattern"], f["projector"], f["out"], f["cols"], f["rows"],
                              f["square_mm"], replace=f["replace"])

    return [
        Route("/api/calibrate", reading(lambda r: calibration.snapshot())),
        Route("/api/calibrate/{action}", wizard, methods=["POST"]),
        Route("/api/calibrate/picture/{name}.png", reading(lambda r: png(
            calibration.pictures.get(r.path_params["name"]), "no such picture yet: capture a pose first"))),
        Route("/api/calibrate-recorded", reading(lambda r: recorded.snapshot())),
        Route("/api/calibrate-recorded/start", action("calibrate-recorded", {
            "captures": text(""), "pattern": text(""), "projector": text(""), "out": text("recorded-rig.json"),
            "cols": given(10), "rows": given(7), "square_mm": given(20.0), "replace": flag(False)}, recorded_start),
            methods=["POST"]),
    ]
