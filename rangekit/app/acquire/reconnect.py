"""A device that went away mid-scan, waited for: :func:`reconnected` decides whether acquisition takes the view
again (:func:`rangekit.app.acquire.acquire.acquire`).

A :class:`DeviceDisconnected` or :class:`DeviceTimeout` from a device with ``reconnect(timeout_s)`` (the drivers of
:mod:`rangekit.drivers`; the simulator's devices have none) is waited for up to the rig file's
``devices.<entry>.reconnect_timeout_s`` (:func:`rangekit.rig.checks.reconnect_timeout_s`, default
:data:`rangekit.rig.checks.DEFAULT_RECONNECT_S`; 0: never wait). Once it is back the view in progress is taken
again from its turntable move, at most :data:`MAX_RETAKES` times.
"""

from __future__ import annotations

from typing import Callable

from rangekit.app.acquire.frame_writer import FrameError
from rangekit.errors import DeviceDisconnected, DeviceError, DeviceTimeout, ProtocolError
from rangekit.progress import LOGGER
from rangekit.rig.checks import reconnect_timeout_s
from rangekit.rig.rig_file import Rig

__all__ = ["MAX_RETAKES", "reconnected"]

#: How often one view is taken again after its device came back; a device that keeps going away ends the scan.
MAX_RETAKES = 3
#: The rig file's ``devices`` entry of each device acquisition calls (the lasers are switched by the turntable).
_RIG_ENTRY = {"turntable": "turntable", "lasers": "turntable", "projector": "projector", "camera": "camera"}


def reconnected(devices, rig: Rig, exc: FrameError, report: Callable[[str], None], n_views: int) -> bool:
    """Whether the device of a disconnection or time-out (``exc.device``) came back: its ``reconnect(timeout_s)``
    returned within the rig file's ``devices.<entry>.reconnect_timeout_s`` (seconds). ``report(msg)`` is told
    of the wait and of the return. When the device did not come back, ``exc.error`` is replaced by what the
    scan ends with: the loss, "not back within ..." (naming the rig-file field), or why the device cannot go
    on (a turntable that lost its origin)."""
    entry = _RIG_ENTRY.get(exc.device)
    reconnect = getattr(getattr(devices, entry, None), "reconnect", None) if entry else None
    if reconnect is None or not isinstance(exc.error, (DeviceDisconnected, DeviceTimeout)):
        return False
    timeout_s = reconnect_timeout_s(rig.devices, entry)
    if timeout_s <= 0:
        return False
    report(f"view {exc.view + 1}/{n_views}: {exc.error}; waiting up to {timeout_s:g} s for it to come back")
    try:
        reconnect(timeout_s)
    except (DeviceDisconnected, DeviceTimeout, ProtocolError) as lost:
        LOGGER.debug("%s: not back: %s", entry, lost)
        exc.error = type(exc.error)(f"{exc.error}; not back within devices.{entry}.reconnect_timeout_s="
                                    f"{timeout_s:g} s")
        return False
    except DeviceError as lost:       # back, but it cannot go on
        exc.error = lost
        return False
    report(f"view {exc.view + 1}/{n_views}: the {exc.device} is back; the view is taken again")
    return True
