"""Live active stereo from an OAK-D (Pro): one synchronised left/right mono pair with the dot projector on.

:func:`capture_stereo_pair` opens the device, builds a depthai v3 pipeline of two ``node.Camera`` on
CAM_B (left) and CAM_C (right) with GRAY8 outputs of one size, joined by a ``node.Sync`` so both frames
of a pair come from one exposure (their sequence numbers are checked too), sets the IR dot projector and
flood light, and returns the pair with both cameras' calibration (world = the left camera, metres). With
``on_device`` it also starts ``node.StereoDepth`` on the same two outputs, aligned to the left camera,
and returns its depth in the same synchronised group; without it no StereoDepth node is created.

depthai is imported inside the function (see :mod:`rangekit.drivers.depthai.camera`, whose device
search, socket and calibration helpers are used here). The emitters are switched off again on close.
"""

from __future__ import annotations

import datetime
import time
from dataclasses import dataclass

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.drivers.depthai.camera import _socket, pinhole_from_calibration
from rangekit.drivers.discovery import open_depthai_device
from rangekit.errors import ConfigError, DeviceDisconnected, DeviceError, DeviceTimeout

__all__ = ["LiveStereoPair", "capture_stereo_pair", "DEPTHAI_STEREO_NAMES", "LEFT", "RIGHT"]

LEFT, RIGHT = "CAM_B", "CAM_C"

#: Every depthai attribute path this module uses beyond depthai_camera's DEPTHAI_NAMES; checked by a test.
DEPTHAI_STEREO_NAMES = [
    "node.Sync", "node.Sync.setSyncThreshold", "node.Sync.inputs", "node.Sync.out", "Node.Output.link",
    "Node.InputMap.__getitem__", "MessageGroup.__getitem__", "ImgFrame.getSequenceNum",
    "node.StereoDepth.setLeftRightCheck",
]


@dataclass(frozen=True, eq=False)
class LiveStereoPair:
    """One synchronised pair. ``left``, ``right``: (H, W) uint8; ``left_camera``, ``right_camera``: the
    device's calibration at that size (world = left camera frame); ``device_depth``: (H, W) float32
    metres along the left camera's axis from the device's StereoDepth, NaN where invalid, or None;
    ``sequence``: the frames' sequence number; ``dots``/``flood``: the emitter powers set, or None when the
    device has no such emitter."""

    left: np.ndarray
    right: np.ndarray
    left_camera: PinholeCamera
    right_camera: PinholeCamera
    device_depth: np.ndarray | None
    sequence: int
    device_id: str
    dots: float | None
    flood: float | None


def _grey(msg) -> np.ndarray:
    return np.asarray(msg.getFrame(), dtype=np.uint8).reshape(msg.getHeight(), msg.getWidth())


def capture_stereo_pair(device_id: str | None = None, *, size: tuple[int, int] = (640, 400), dots: float = 0.8,
                        flood: float = 0.0, on_device: bool = False, search_timeout_s: float = 3.0,
                        frame_timeout_s: float = 3.0, settle_frames: int = 3,
                        sync_threshold_ms: float = 5.0) -> LiveStereoPair:
    """Capture one synchronised left/right pair from an attached OAK-D (module doc).

    Parameters
    ----------
    device_id : device id (MXID), name or IP; the first device found when omitted.
    size : (width, height) of both mono outputs (``ImgResizeMode.CROP``; intrinsics rescaled to it).
    dots, flood : IR dot projector and flood light power in [0, 1] (active stereo: dots on, flood off).
    on_device : also run the device's StereoDepth for comparison.
    settle_frames : synchronised pairs dropped first, so the emitters' new power is in the frames.
    sync_threshold_ms : largest timestamp difference the Sync node pairs.

    Raises
    ------
    ConfigError for a power outside [0, 1]; DeviceDisconnected if no device answers; DeviceError if it
    lacks CAM_B/CAM_C, has no dot projector while ``dots`` > 0, or the pipeline cannot start;
    DeviceTimeout if no pair with matching sequence numbers arrives within ``frame_timeout_s``.
    """
    for name, value in (("dots", dots), ("flood", flood)):
        if not (isinstance(value, (int, float)) and 0.0 <= value <= 1.0):
            raise ConfigError(f"capture_stereo_pair: {name} must be a power in [0, 1], found {value!r}")
    import depthai as dai

    size = (int(size[0]), int(size[1]))
    device = open_depthai_device(dai, device_id, search_timeout_s)
    name = f"depthai {device.getDeviceId()}"
    pipeline = None
    try:
        connected = set(device.getConnectedCameras())
        socks = [_socket(dai, s) for s in (LEFT, RIGHT)]
        if not all(s in connected for s in socks):
            raise DeviceError(f"{name}: active stereo needs mono cameras on {LEFT} and {RIGHT}; this device has "
                              f"{sorted(s.name for s in connected)}")
        handler = device.readCalibration()
        left_cam = pinhole_from_calibration(handler, LEFT, size)
        right_cam = pinhole_from_calibration(handler, RIGHT, size, world_socket=LEFT)
        pipeline = dai.Pipeline(device)
        outs = [pipeline.create(dai.node.Camera).build(s).requestOutput(size, dai.ImgFrame.Type.GRAY8,
                                                                       dai.ImgResizeMode.CROP) for s in socks]
        sync = pipeline.create(dai.node.Sync)
        sync.setSyncThreshold(datetime.timedelta(milliseconds=sync_threshold_ms))
        outs[0].link(sync.inputs["left"])
        outs[1].link(sync.inputs["right"])
        if on_device:
            stereo = pipeline.create(dai.node.StereoDepth).build(outs[0], outs[1],
                                                                 dai.node.StereoDepth.PresetMode.DEFAULT)
            stereo.setLeftRightCheck(True)
            stereo.setDepthAlign(socks[0])
            stereo.setOutputSize(*size)
            stereo.depth.link(sync.inputs["depth"])
        queue = sync.out.createOutputQueue(maxSize=4, blocking=False)
        dots_set = float(dots) if device.setIrLaserDotProjectorIntensity(float(dots)) else None
        flood_set = float(flood) if device.setIrFloodLightIntensity(float(flood)) else None
        if dots > 0 and dots_set is None:
            raise DeviceError(f"{name}: this model has no IR dot projector (an OAK-D Pro has one); pass --dots 0 "
                              "for passive stereo on a textured scene")
        pipeline.start()
        group = _synchronised_group(dai, queue, name, frame_timeout_s, settle_frames, on_device)
        left, right = group["left"], group["right"]
        depth = None
        if on_device:
            d = group["depth"]
            mm = np.asarray(d.getFrame()).reshape(d.getHeight(), d.getWidth())
            depth = mm.astype(np.float32) * np.float32(1e-3)
            depth[mm == 0] = np.nan
        return LiveStereoPair(_grey(left), _grey(right), left_cam, right_cam, depth, int(left.getSequenceNum()),
                              device.getDeviceId(), dots_set, flood_set)
    except RuntimeError as exc:
        raise DeviceError(f"{name}: stereo pipeline failed: {exc}") from exc
    finally:
        try:
            if pipeline is not None and pipeline.isRunning():
                pipeline.stop()
            device.setIrLaserDotProjectorIntensity(0.0)
        finally:
            device.close()


def _synchronised_group(dai, queue, name: str, timeout_s: float, settle: int, depth: bool):
    """The first Sync group after ``settle`` dropped ones whose left and right sequence numbers agree."""
    deadline = time.monotonic() + timeout_s
    seen = 0
    while True:
        left = deadline - time.monotonic()
        if left <= 0:
            raise DeviceTimeout(f"{name}: no synchronised left/right pair within {timeout_s:.1f} s (after "
                                f"{seen} groups); check the cable and that both mono cameras stream")
        try:
            group = queue.get(datetime.timedelta(seconds=left))
        except (RuntimeError, dai.MessageQueue.QueueException) as exc:
            raise DeviceDisconnected(f"{name}: stream closed while waiting for a stereo pair: {exc}; replug the "
                                     "device") from exc
        if group is None:
            continue
        seen += 1
        if seen <= settle:
            continue
        if group["left"].getSequenceNum() == group["right"].getSequenceNum():
            return group
