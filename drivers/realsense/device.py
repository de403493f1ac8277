"""The pyrealsense2 boundary: find a RealSense by serial number or open a recording, set an option and read it
back, and turn a stream's intrinsics into a :class:`rangekit.camera.PinholeCamera`.

pyrealsense2 is imported inside the functions, never at module level (``import rangekit.drivers.realsense``
works without it; :func:`rangekit.drivers.cameras.camera_driver` names the extra when it is missing).

Conventions at this boundary:

- Pixels: librealsense's pixel coordinates put the centre of the top-left pixel at (0, 0), as rangekit's do, so
  ``ppx``, ``ppy`` are the principal point unchanged.
- Lens: ``brown_conrady`` coefficients are OpenCV's ``k1 k2 p1 p2 k3`` (librealsense's forward model since 2.x is
  OpenCV's); any model with all-zero coefficients is a plain pinhole (a D4xx's depth and infrared streams are
  rectified and report zeros). Another model with non-zero coefficients (``inverse_brown_conrady``,
  ``modified_brown_conrady``, fisheye) is refused: rangekit's lens model cannot hold it.
- Recordings: ``.db3`` (ROS2 rosbag, what pyrealsense2 2.57+ writes) and ``.bag`` (ROS1, what older SDKs and
  the RealSense Viewer wrote) both open through ``context.load_device``; a recording plays as recorded, not in
  real time (every frame delivered), and its options are the recorded values, read-only.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.errors import ConfigError, DeviceDisconnected, DeviceError, FileFormatError, one_line

__all__ = ["RECORDING_SUFFIXES", "find_device", "open_recording", "set_option", "read_option", "pinhole_from_intrinsics",
           "device_serial", "stream_sensor", "CHECK_CABLE"]

#: What a RealSense recording's file name ends with.
RECORDING_SUFFIXES = (".bag", ".db3")
#: What a lost or silent RealSense's message says to check.
CHECK_CABLE = "check its USB 3 cable and power (was it unplugged or reset?)"


def device_serial(rs, device) -> str:
    """The device's serial number ("" when it has none)."""
    return device.get_info(rs.camera_info.serial_number) if device.supports(rs.camera_info.serial_number) else ""


def _serials(rs, ctx) -> list[str]:
    return [device_serial(rs, d) for d in ctx.query_devices()]


def find_device(rs, ctx, serial: str | None, timeout_s: float):
    """The device of ``ctx`` with serial number ``serial`` (None: the first one), polled for up to ``timeout_s``
    seconds (a device that is enumerating again after a reset shows up within that time).

    Raises DeviceDisconnected naming the serial and the serial numbers found when none matches in time."""
    who = f"RealSense {serial}" if serial else "a RealSense camera"
    deadline = time.monotonic() + float(timeout_s)
    while True:
        try:
            devices = list(ctx.query_devices())
        except RuntimeError as exc:
            raise DeviceError(f"{who}: the device search failed: {one_line(exc)}") from exc
        for device in devices:
            if serial is None or device_serial(rs, device) == serial:
                return device
        if time.monotonic() >= deadline:
            found = [device_serial(rs, d) for d in devices]
            seen = f"found only {', '.join(found)}" if found else "none is attached"
            raise DeviceDisconnected(f"{who}: not found within {float(timeout_s):g} s ({seen}); {CHECK_CABLE}, list "
                                     "cameras with 'rangekit devices', or set devices.camera.serial to one listed")
        time.sleep(min(0.1, max(0.0, deadline - time.monotonic())))


def open_recording(rs, ctx, path: str | Path) -> str:
    """Check that ``path`` is a RealSense recording (``.bag`` or ``.db3``) the SDK can play; returns the serial number
    of the camera it recorded.

    Raises FileFormatError, one line naming the file, when it is missing, has another suffix or is not a
    recording the SDK can read."""
    path = Path(path)
    if path.suffix.lower() not in RECORDING_SUFFIXES:
        raise FileFormatError(f"{path}: a RealSense recording ends with {' or '.join(RECORDING_SUFFIXES)}, found "
                              f"{path.suffix or 'no suffix'!r}; record one with the RealSense Viewer or rs.recorder")
    if not path.is_file():
        raise FileFormatError(f"{path}: no such recording (devices.camera.bag); check the path")
    try:
        device = ctx.load_device(str(path))
    except RuntimeError as exc:
        raise FileFormatError(f"{path}: not a RealSense recording the SDK can read ({one_line(exc)}); expected a "
                              ".bag (ROS1) or .db3 (ROS2) file written by the RealSense Viewer or rs.recorder") from exc
    serial = device_serial(rs, device)
    ctx.unload_device(str(path))      # checked only: the pipeline plays the file itself (its own playback device)
    return serial


def stream_sensor(rs, device, stream, name: str):
    """The sensor of ``device`` that has a ``stream`` (an ``rs.stream``) profile; DeviceError naming the device
    when none has."""
    for sensor in device.query_sensors():
        if any(p.stream_type() == stream for p in sensor.get_stream_profiles()):
            return sensor
    raise DeviceError(f"{name}: has no {stream.name} stream (a RealSense D400/D500 has one on its Stereo Module)")


def read_option(rs, sensor, option) -> float | None:
    """The option's present value, or None when the sensor does not have it."""
    return float(sensor.get_option(option)) if sensor.supports(option) else None


def set_option(rs, sensor, option, value: float, *, name: str, field: str) -> float:
    """Set ``option`` to ``value`` and read it back; returns the value read.

    ``field`` (the rig file's name for it, ``capture.camera.exposure_us``) and ``name`` (the device) go into the
    one-line DeviceError raised when the sensor lacks the option, it is read-only (a recording), ``value`` is
    outside its range, the SDK refuses it, or the value read back differs (a control the camera ignored)."""
    what = f"{name}: {field} = {value:g} ({option.name})"
    if not sensor.supports(option):
        raise DeviceError(f"{what}: this sensor has no such control; drop {field} from the rig file")
    if sensor.is_option_read_only(option):
        raise DeviceError(f"{what}: the control is read-only here (a recording plays the values it was recorded "
                          f"with: {float(sensor.get_option(option)):g})")
    r = sensor.get_option_range(option)
    if not r.min - 1e-9 <= value <= r.max + 1e-9:
        raise DeviceError(f"{what}: outside the camera's range {r.min:g}..{r.max:g} (step {r.step:g}); change {field}")
    try:
        sensor.set_option(option, float(value))
    except RuntimeError as exc:
        raise DeviceError(f"{what}: refused by the camera ({one_line(exc)}); change {field}") from exc
    got = float(sensor.get_option(option))
    if abs(got - value) > max(r.step, 1e-6) / 2:
        raise DeviceError(f"{what}: the camera reads back {got:g}, it ignored the setting; a scan needs the value "
                          "it asked for (check the firmware, or lower the frame rate)")
    return got


def pinhole_from_intrinsics(rs, intrinsics, *, name: str, where: str) -> PinholeCamera:
    """The :class:`PinholeCamera` of an ``rs.intrinsics`` (module doc: pixels, lens); ``T_world_cam`` = I.

    Raises ConfigError naming ``where`` for a lens model rangekit cannot hold."""
    coeffs = np.asarray(list(intrinsics.coeffs), dtype=np.float64)[:5]
    model = intrinsics.model
    if not np.any(coeffs != 0):
        dist = np.zeros(5)
    elif model == rs.distortion.brown_conrady:
        dist = coeffs
    else:
        raise ConfigError(f"{where}: lens model {model.name} with coefficients {coeffs.tolist()} is not supported "
                          "(rangekit holds OpenCV's Brown-Conrady); use a rectified stream (depth, infrared) or "
                          "calibrate this one")
    K = np.array([[intrinsics.fx, 0.0, intrinsics.ppx], [0.0, intrinsics.fy, intrinsics.ppy], [0.0, 0.0, 1.0]])
    return PinholeCamera(K, int(intrinsics.width), int(intrinsics.height), dist, np.eye(4), name)
