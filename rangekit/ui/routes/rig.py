"""The rig's routes (the Live page's controls): ``GET /api/status`` (the devices' status), ``POST /api/reconnect``
(hardware: open the devices again), ``POST /api/pattern`` ``{"name"}``, ``POST /api/turntable`` ``{"degrees"}`` or
``{"home": true}``, ``POST /api/camera`` ``{"exposure_us", "iso", "white_balance_k", "focus"}`` (any of them:
written into the rig file's ``capture.camera``, then applied)."""

from __future__ import annotations

from rangekit.errors import RangekitError
from rangekit.ui.guard.fields import Field, flag, number, take, text
from rangekit.ui.routes.common import Ui, action, given, reading

__all__ = ["CAMERA_FIELDS", "MAX_JOG_DEG", "routes", "status_body"]

#: The camera controls the Live page sets (the rig file's capture.camera fields).
CAMERA_FIELDS = ("exposure_us", "iso", "white_balance_k", "focus")
#: The largest turntable jog (degrees, either way).
MAX_JOG_DEG = 360.0


def _camera_value(name, value):
    if isinstance(value, (bool, list, dict)) or value is None:
        raise RangekitError(f"camera: {name}: expected a number or 'auto', found {value!r}"[:200])
    return value


def status_body(ui: Ui) -> dict:
    """What ``GET /api/status`` answers, and ``/ws/jobs`` sends as ``{"rig": ...}`` when it changes: the rig's
    status, the patterns it shows, the live stream's error."""
    from rangekit.ui.rig_holder import PATTERNS

    return {"rig": ui.holder.status(), "patterns": list(PATTERNS), "live_error": ui.stream.error}


def routes(ui: Ui) -> list:
    from starlette.routing import Route

    holder = ui.holder

    def rig(*_):
        return {"rig": holder.status()}

    def pattern(request, f):
        holder.show_pattern(f["name"])
        return rig()

    def turntable(request, f):
        if f["home"]:
            holder.turn(home=True)
        elif f["degrees"] is None:
            raise RangekitError(f"degrees: missing; expected a number -{MAX_JOG_DEG:g} to {MAX_JOG_DEG:g} "
                                "(or home: true)")
        else:
            holder.turn(degrees=f["degrees"])
        return rig()

    def camera(request, body):
        unknown = sorted(set(body) - set(CAMERA_FIELDS))
        if unknown:
            raise RangekitError(f"camera: {str(unknown[0])[:80]}: not a control here; expected "
                                f"{', '.join(CAMERA_FIELDS)}")
        spec = {name: Field(_camera_value, None) for name in CAMERA_FIELDS}
        holder.set_camera({k: v for k, v in take(body, spec, "camera").items() if k in body})
        return rig()

    return [
        Route("/api/status", reading(lambda r: status_body(ui))),
        Route("/api/pattern", action("pattern", {"name": text()}, pattern), methods=["POST"]),
        Route("/api/reconnect", action("reconnect", {}, lambda r, f: {"rig": holder.connect()}), methods=["POST"]),
        Route("/api/turntable", action("turntable", {"degrees": number(-MAX_JOG_DEG, MAX_JOG_DEG, None),
                                                     "home": flag(False)}, turntable), methods=["POST"]),
        Route("/api/camera", action("camera", {n: given() for n in CAMERA_FIELDS}, camera, checked=False),
              methods=["POST"]),
    ]

