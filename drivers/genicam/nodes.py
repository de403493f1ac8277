"""A GenICam camera's node map written from the rig file, every value read back.

GenICam names a camera's features as the nodes of its node map, with standard names (SFNC); older cameras use
older names, tried second. The rig file's ``capture.camera`` (:class:`rangekit.rig.camera_controls.CameraControls`)
and the ``devices.camera`` section map onto them as follows (docs/hardware.md, "GenICam cameras"):

=========================  ===========================================================================================
``exposure_us`` E          ``ExposureAuto`` Off, ``ExposureTime`` E (microseconds; ``ExposureTimeAbs``);
                           ``"auto"``: ``ExposureAuto`` Continuous
``iso`` I                  ``GainAuto`` Off, ``Gain`` 20 log10(I / 100) dB (ISO 100 = 0 dB); ``"auto"``: ``GainAuto``
                           Continuous
``white_balance_k``        ``BalanceWhiteAuto`` Off (GenICam sets a balance by ratios, not a temperature: the
                           camera keeps the ratios it has); ``"auto"``: Continuous; ``"mono"``: Off, frames grey
``focus``                  not written: a machine-vision lens is focused by its ring
``fps`` F                  ``AcquisitionFrameRateEnable`` true, ``AcquisitionFrameRate`` F (``AcquisitionFrameRateAbs``)
``pixel_format``           ``PixelFormat`` (section; before the stream starts), with ``Width`` and ``Height`` of the
                           rig's ``cameras[0]``
``trigger_source`` S       ``TriggerSelector`` FrameStart, ``TriggerMode`` On, ``TriggerSource`` S (``Software`` or a
                           line, e.g. ``Line1`` wired to the projector's VSYNC), ``TriggerActivation`` (a line's
                           edge, section ``trigger_activation``); null: ``TriggerMode`` Off (free-running)
=========================  ===========================================================================================

Every write is read back from the device (genapi's cache bypassed): a value the camera changed (beyond its increment, or 1 % of a number) or refused is a
:class:`DeviceError` naming the device, the node, what was written and what was read or why it was refused. A node
the device lacks is one of its *limits*: a line saying what is not applied, kept on the camera
(``GenicamCamera.limits``) and shown by ``rangekit check``, never an error.
"""

from __future__ import annotations

import math

from rangekit.errors import DeviceError, one_line
from rangekit.rig.camera_controls import CameraControls

__all__ = ["find_node", "set_node", "apply_controls", "apply_format", "apply_trigger", "gain_db"]


def gain_db(iso: int) -> float:
    """The GenICam ``Gain`` (dB) of an ISO number: ISO 100 is the sensor's own gain, 0 dB; each doubling +6.02 dB."""
    return 20.0 * math.log10(float(iso) / 100.0)


def find_node(nm, names: tuple[str, ...]):
    """(name, node) of the first of ``names`` the node map has and implements, or (names[0], None)."""
    from genicam.genapi import is_implemented

    for name in names:
        try:
            if nm.has_node(name):
                node = nm.get_node(name)
                if is_implemented(node):
                    return name, node
        except Exception:  # noqa: BLE001 - genapi raises its own exceptions for a node it cannot resolve
            continue
    return names[0], None


def _reason(exc: BaseException) -> str:
    """A genapi exception's own sentence, without the source file and line it appends."""
    text = str(exc).split(" : ")[0].split("(file ")[0].strip()
    return one_line(text or type(exc).__name__)


def _takes(node) -> str:
    """What a node takes, for an error: its symbolics, or its range and increment."""
    symbolics = getattr(node, "symbolics", None)
    if symbolics:
        return "the device takes " + ", ".join(map(str, symbolics))
    try:
        inc = f" in steps of {node.inc:g}" if getattr(node, "has_inc", lambda: False)() else ""
        return f"the device takes {node.min:g}..{node.max:g}{inc}"
    except Exception:  # noqa: BLE001 - a node without a readable range
        return "see the camera's manual for the range"


def _close_enough(got, want, node) -> bool:
    if isinstance(want, bool) or isinstance(want, str):
        return got == want
    inc = 0.0
    try:
        if getattr(node, "has_inc", lambda: False)():
            inc = float(node.inc)
    except Exception:  # noqa: BLE001 - no increment to read
        pass
    return abs(float(got) - float(want)) <= max(inc, 0.01 * abs(float(want)), 1e-9)


def _device_value(node):
    """The node's value read from the device, not from genapi's cache (a write-through cache would give back what
    was written, whatever the camera made of it)."""
    try:
        return node.get_value(False, True)
    except TypeError:       # a node type whose get_value takes no such arguments
        return node.value


def set_node(nm, names: tuple[str, ...], value, *, device: str, limits: list, unapplied: str):
    """Write ``value`` into the first of ``names`` the device has and read it back; the value read.

    A device without the node: ``unapplied`` (what is therefore not applied) is appended to ``limits`` and None
    returned. A node that is not writable, a value refused or read back otherwise: DeviceError naming ``device``."""
    from genicam.genapi import GenericException, is_writable

    name, node = find_node(nm, names)
    if node is None:
        limits.append(f"no {name} node: {unapplied}")
        return None
    if isinstance(value, str) and getattr(node, "symbolics", None) and value not in node.symbolics:
        raise DeviceError(f"{device}: node {name} has no value {value!r}; {_takes(node)}")
    if not is_writable(node):
        raise DeviceError(f"{device}: node {name} is not writable now (writing {value!r}); check that no other "
                          "program holds the camera and that the node is not locked by another setting")
    try:
        node.value = value
        got = _device_value(node)
    except GenericException as exc:
        raise DeviceError(f"{device}: node {name} refused {value!r} ({_reason(exc)}); {_takes(node)}") from None
    if not _close_enough(got, value, node):
        raise DeviceError(f"{device}: node {name}: wrote {value!r}, read back {got!r}; the camera did not take it "
                          f"({_takes(node)})")
    return got


def _auto(nm, node: str, on: bool, *, device: str, limits: list, what: str) -> None:
    """``node`` (ExposureAuto, GainAuto, BalanceWhiteAuto) Continuous or Off, read back. A device without it has no
    automatic control to switch off; asked to be automatic, that is a limit."""
    if find_node(nm, (node,))[1] is None and not on:
        return
    set_node(nm, (node,), "Continuous" if on else "Off", device=device, limits=limits,
             unapplied=f"the device has no automatic {what}; capture.camera asks for it")


def apply_controls(nm, controls: CameraControls, *, device: str) -> list[str]:
    """Write ``controls`` (all but ``focus``) as the module docstring's table says; the device's limits met."""
    limits: list[str] = []
    _auto(nm, "ExposureAuto", controls.exposure_us is None, device=device, limits=limits, what="exposure")
    if controls.exposure_us is not None:
        set_node(nm, ("ExposureTime", "ExposureTimeAbs"), float(controls.exposure_us), device=device, limits=limits,
                 unapplied=f"capture.camera.exposure_us {controls.exposure_us:g} is not applied, the device exposes "
                           "as it does")
    _auto(nm, "GainAuto", controls.iso is None, device=device, limits=limits, what="gain")
    if controls.iso is not None:
        set_node(nm, ("Gain",), gain_db(controls.iso), device=device, limits=limits,
                 unapplied=f"capture.camera.iso {controls.iso} is not applied, the device's gain is kept")
    wb_auto = controls.white_balance_k is None and not controls.mono
    _auto(nm, "BalanceWhiteAuto", wb_auto, device=device, limits=limits, what="white balance")
    if find_node(nm, ("AcquisitionFrameRateEnable",))[1] is not None:
        set_node(nm, ("AcquisitionFrameRateEnable",), True, device=device, limits=limits, unapplied="")
    set_node(nm, ("AcquisitionFrameRate", "AcquisitionFrameRateAbs"), float(controls.fps), device=device,
             limits=limits, unapplied=f"capture.camera.fps {controls.fps:g} is not applied, the device runs at "
                                      "its own rate")
    return limits


def apply_format(nm, pixel_format: str, size: tuple[int, int], *, device: str) -> list[str]:
    """``PixelFormat``, ``Width`` and ``Height`` (the rig camera's ``size``), written before the stream starts;
    the device's limits met."""
    limits: list[str] = []
    set_node(nm, ("PixelFormat",), pixel_format, device=device, limits=limits,
             unapplied=f"devices.camera.pixel_format {pixel_format} is not applied, frames come as the device sends")
    for name, value in (("Width", size[0]), ("Height", size[1])):
        set_node(nm, (name,), int(value), device=device, limits=limits,
                 unapplied=f"the frame {name.lower()} is the device's own (the rig's cameras[0] says {value})")
    return limits


def apply_trigger(nm, source: str | None, activation: str, *, device: str) -> tuple[bool, list[str]]:
    """The frame-start trigger: (whether frames are triggered, the device's limits met). ``source`` None:
    free-running (``TriggerMode`` Off where the device has it). A device without triggers runs free, a limit."""
    limits: list[str] = []
    if find_node(nm, ("TriggerSelector",))[1] is not None:
        set_node(nm, ("TriggerSelector",), "FrameStart", device=device, limits=limits, unapplied="")
    if source is None:
        if find_node(nm, ("TriggerMode",))[1] is not None:
            set_node(nm, ("TriggerMode",), "Off", device=device, limits=limits, unapplied="")
        return False, limits
    if find_node(nm, ("TriggerMode",))[1] is None:
        limits.append(f"no TriggerMode node: devices.camera.trigger_source {source} is not applied, the device "
                      "runs free and each capture flushes its buffers (devices.camera.flush_frames)")
        return False, limits
    set_node(nm, ("TriggerMode",), "On", device=device, limits=limits, unapplied="")
    set_node(nm, ("TriggerSource",), source, device=device, limits=limits,
             unapplied=f"the trigger source is the device's own (devices.camera.trigger_source {source})")
    if source != "Software":
        set_node(nm, ("TriggerActivation",), activation, device=device, limits=limits,
                 unapplied=f"the trigger edge is the device's own (devices.camera.trigger_activation {activation})")
    return True, limits
