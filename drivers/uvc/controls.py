"""The rig file's camera controls (:class:`rangekit.rig.camera_controls.CameraControls`) as V4L2 controls of a UVC
webcam, written and verified by reading them back.

Many webcams accept a write and keep their own value (the exposure most of all, while some auto mode is still on):
every control written is read back (``VIDIOC_G_CTRL``) and a difference refuses the camera, one line naming the
device, the control, the value written and the value read. The mapping, one field at a time (docs/hardware.md):

===========================  ==========================================================================================
``exposure_us`` E            ``exposure_auto`` = 1 (manual), ``exposure_auto_priority`` = 0 (the frame rate is kept),
                             ``exposure_absolute`` = round(E / 100) (V4L2's unit is 100 us)
``exposure_us`` ``"auto"``   ``exposure_auto`` = 3 (aperture priority, the UVC auto mode; 0 where the menu ends below)
``iso`` I                    ``gain`` = the device's minimum at ISO 100, its maximum at ISO 1600, linear between
                             (UVC gain has no unit); ``"auto"``: the gain is left as it is
``white_balance_k`` K        ``white_balance_automatic`` = 0, ``white_balance_temperature`` = K;
                             ``"auto"``: automatic 1; ``"mono"``: automatic 0 (held where it is), frames grey
``focus`` F                  ``focus_automatic_continuous`` = 0, ``focus_absolute`` = F (the device's units);
                             ``"auto"`` with ``lock_focus``: automatic 0 (held where it is); without: automatic 1
===========================  ==========================================================================================

The automatic modes are switched off before the values are written (a webcam ignores a manual exposure while its
auto-exposure is on). Every value is rounded to the control's step; a value outside the control's range is refused
naming the rig-file field and the range. A control the device lacks is a limit, said in words (:attr:`Applied.limits`:
a fixed-focus lens has no focus control), except the exposure of a camera opened for coded light, which must lock.
"""

from __future__ import annotations

from dataclasses import dataclass

from rangekit.rig.camera_controls import CONTROL_FIELDS, CameraControls
from rangekit.errors import DeviceError

__all__ = ["Applied", "planned_writes", "apply_controls", "verify", "EXPOSURE_UNIT_US"]

#: V4L2's ``exposure_absolute`` unit, microseconds.
EXPOSURE_UNIT_US = 100.0
_MANUAL, _APERTURE_PRIORITY, _AUTO = 1, 3, 0
_ISO_LO, _ISO_HI = CONTROL_FIELDS["iso"][:2]


@dataclass(frozen=True)
class Applied:
    """What :func:`apply_controls` did: ``writes`` ((control, value) in device units, in order, each read back
    equal), ``limits`` what the device lacks, one line each."""

    writes: tuple[tuple[str, int], ...]
    limits: tuple[str, ...]


@dataclass(frozen=True)
class _Write:
    control: str
    value: int
    field: str        # the rig file's field it comes from


def _on_step(info, value: float, field: str, shown: str, name: str) -> int:
    """``value`` (device units) rounded to ``info``'s step; out of its range: a DeviceError naming ``field``."""
    if not info.minimum - 0.5 <= value <= info.maximum + 0.5:
        raise DeviceError(f"{name}: {field} {shown} is {info.name} {value:g}, outside the camera's range "
                          f"{info.minimum}..{info.maximum}; choose a value inside it")
    step = max(int(info.step), 1)
    return int(min(max(info.minimum + round((value - info.minimum) / step) * step, info.minimum), info.maximum))


def _exposure(node, c: CameraControls, out: list, limits: list) -> None:
    mode, absolute = node.query("exposure_auto"), node.query("exposure_absolute")
    field = "capture.camera.exposure_us"
    if c.exposure_us is None:
        if mode is not None:
            out.append(_Write("exposure_auto", _APERTURE_PRIORITY if mode.maximum >= _APERTURE_PRIORITY else _AUTO,
                              field))
        return
    if mode is None or absolute is None or not absolute.writable:
        limits.append(f"exposure: no {'exposure_auto' if mode is None else 'exposure_absolute'} control, the "
                      "exposure cannot be set or locked")
        return
    out.append(_Write("exposure_auto", _MANUAL, field))
    priority = node.query("exposure_auto_priority")
    if priority is not None and priority.writable:
        out.append(_Write("exposure_auto_priority", 0, field))
    value = _on_step(absolute, c.exposure_us / EXPOSURE_UNIT_US, field, f"{c.exposure_us:g} us", node.name)
    out.append(_Write("exposure_absolute", value, field))


def _gain(node, c: CameraControls, out: list, limits: list) -> None:
    gain = node.query("gain")
    if gain is None or not gain.writable:
        limits.append("gain: no gain control, the sensor's gain is the camera's own")
    elif c.iso is not None:
        value = gain.minimum + (c.iso - _ISO_LO) / (_ISO_HI - _ISO_LO) * (gain.maximum - gain.minimum)
        out.append(_Write("gain", _on_step(gain, value, "capture.camera.iso", str(c.iso), node.name),
                          "capture.camera.iso"))


def _white_balance(node, c: CameraControls, out: list, limits: list) -> None:
    auto, temperature = node.query("white_balance_automatic"), node.query("white_balance_temperature")
    field = "capture.camera.white_balance_k"
    if auto is not None:
        out.append(_Write("white_balance_automatic", int(c.white_balance_k is None and not c.mono), field))
    if c.white_balance_k is None or c.mono:
        if auto is None:
            limits.append("white balance: no white_balance_automatic control, the balance is the camera's own")
        return
    if temperature is None or not temperature.writable:
        limits.append("white balance: no white_balance_temperature control, the balance is held where it is"
                      if auto is not None else "white balance: no white balance control, the balance is the "
                      "camera's own")
        return
    out.append(_Write("white_balance_temperature",
                      _on_step(temperature, c.white_balance_k, field, f"{c.white_balance_k} K", node.name), field))


def _focus(node, c: CameraControls, out: list, limits: list) -> None:
    auto, absolute = node.query("focus_automatic_continuous"), node.query("focus_absolute")
    field = "capture.camera.focus"
    if auto is None and absolute is None:
        limits.append("focus: no focus control (a fixed-focus lens), the focus stays where it is")
        return
    if auto is not None:
        out.append(_Write("focus_automatic_continuous", int(c.focus is None and not c.lock_focus), field))
    if c.focus is not None:
        if absolute is None or not absolute.writable:
            limits.append("focus: no focus_absolute control, the lens is held where it is")
            return
        out.append(_Write("focus_absolute", _on_step(absolute, c.focus, field, str(c.focus), node.name), field))


def planned_writes(node, controls: CameraControls) -> tuple[list[_Write], list[str]]:
    """The V4L2 writes of ``controls`` on ``node`` (queried, nothing written): the automatic modes first, then the
    values; and what the device lacks."""
    out: list[_Write] = []
    limits: list[str] = []
    for part in (_exposure, _gain, _white_balance, _focus):
        part(node, controls, out, limits)
    modes = [w for w in out if w.control in ("exposure_auto", "exposure_auto_priority", "white_balance_automatic",
                                             "focus_automatic_continuous")]
    return modes + [w for w in out if w not in modes], limits


def apply_controls(node, controls: CameraControls) -> Applied:
    """Write ``controls`` to the webcam at ``node`` (:class:`rangekit.drivers.uvc.v4l2.V4l2Node`) and read every
    control back. A refused write or a read-back that differs is a DeviceError, one line naming the device, the
    control, the value written and read, and what to check."""
    writes, limits = planned_writes(node, controls)
    for w in writes:
        node.write(w.control, w.value)
    applied = Applied(tuple((w.control, w.value) for w in writes), tuple(limits))
    verify(node, applied, fields={w.control: w.field for w in writes})
    return applied


def verify(node, applied: Applied, *, fields: dict | None = None, when: str = "") -> None:
    """Read every control of ``applied`` back; one that differs is a DeviceError naming the device, the control,
    the value written and read (``fields``: the rig-file field of each control; ``when``: after what)."""
    for control, value in applied.writes:
        got = node.read(control)
        if got != value:
            field = (fields or {}).get(control)
            raise DeviceError(f"{node.name}: the camera ignores {control}: wrote {value}, read back {got}"
                              f"{f' ({field})' if field else ''}{when}; a control that does not hold changes the "
                              "frames between patterns, so the camera is refused: check that no other program (a "
                              "browser, guvcview) sets it, or use another camera")
