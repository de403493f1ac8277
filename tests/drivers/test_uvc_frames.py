"""The uvc driver's frame path on OpenCV reading a recorded file: the recording is written with cv2.VideoWriter
(MJPEG in an AVI, as a webcam's MJPEG stream) and read by :class:`UvcCamera` through the code a device goes
through (OpenCV's VideoCapture, the size check, the flush of queued frames, the RGB/grey conversion); the rig
file's section, open_rig_devices, and a device lost and back (the recording's node removed and its stream ended).
No webcam here: what OpenCV's V4L2 backend does with a real one is untested (docs/hardware.md).
"""

from __future__ import annotations

import json
import os

import cv2
import numpy as np
import pytest

from rangekit.errors import ConfigError, DeviceDisconnected, DeviceError
from rangekit.rig.camera_controls import CameraControls

W, H, N = 64, 48, 12


def _level(i: int) -> int:
    return 10 + 20 * i


@pytest.fixture
def recording(tmp_path):
    """N flat frames, frame i at grey level 10 + 20 i (MJPEG keeps a flat level within 1)."""
    path = tmp_path / "webcam.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 30, (W, H))
    for i in range(N):
        writer.write(np.full((H, W, 3), _level(i), np.uint8))
    writer.release()
    return path


def _index(frame) -> int:
    return int(round((float(np.mean(frame)) - 10) / 20))


def test_frames_of_a_recording_in_order_rgb_and_grey(recording):
    from rangekit.drivers.uvc.camera import UvcCamera

    with UvcCamera(str(recording), size=(W, H), flush_frames=0) as cam:
        frames = [cam.capture() for _ in range(3)]
        assert cam.limits == ("a recording: no camera controls, frames in the order recorded",)
    assert all(f.shape == (H, W, 3) and f.dtype == np.uint8 for f in frames)
    assert [_index(f) for f in frames] == [0, 1, 2]
    with UvcCamera(str(recording), size=(W, H), flush_frames=0, controls=CameraControls(white_balance_k=None,
                                                                                          mono=True)) as cam:
        grey = cam.capture()
    assert grey.shape == (H, W) and grey.dtype == np.uint8 and abs(float(grey.mean()) - _level(0)) <= 1


def test_each_capture_drops_the_flush_frames(recording):
    from rangekit.drivers.uvc.camera import UvcCamera

    with UvcCamera(str(recording), size=(W, H), flush_frames=2) as cam:
        got = [_index(cam.capture()) for _ in range(3)]
        assert _index(cam.unflushed_frame()) == 9          # the next frame, nothing dropped
        with pytest.raises(DeviceError, match=r"the recording ended after 12 frames"):
            cam.capture()
    assert got == [2, 5, 8]


def test_a_size_the_source_does_not_give_is_one_line(recording):
    from rangekit.drivers.uvc.camera import UvcCamera

    with pytest.raises(DeviceError) as exc:
        UvcCamera(str(recording), size=(640, 480))
    assert str(exc.value) == (f"uvc {recording}: the recording's frames are 64x48; set cameras[0].width and height "
                              "to a size it has")
    with pytest.raises(ConfigError, match="devices.camera.format: expected one of MJPEG, YUYV, found 'H264'"):
        UvcCamera(str(recording), size=(W, H), format="H264")


def _rig_file(tmp_path, camera: dict) -> str:
    from rangekit.rig.rig_file import template_rig

    data = template_rig(camera="uvc")
    data["devices"] = {"camera": camera}
    data["cameras"][0].update(width=W, height=H, K=[[60.0, 0.0, 31.5], [0.0, 60.0, 23.5], [0.0, 0.0, 1.0]])
    path = tmp_path / "rig.json"
    path.write_text(json.dumps(data))
    return str(path)


def test_the_rig_file_section_opens_the_camera(recording, tmp_path):
    from rangekit.drivers import open_rig_devices
    from rangekit.rig.checks import CAMERA_TEMPLATES, UVC_FORMATS
    from rangekit.drivers.uvc.camera import FOURCC
    from rangekit.rig.rig_file import load_rig

    assert tuple(FOURCC) == UVC_FORMATS
    assert CAMERA_TEMPLATES["uvc"] == {"type": "uvc", "device": "/dev/video0", "format": "MJPEG", "flush_frames": 4}
    rig = load_rig(_rig_file(tmp_path, {"type": "uvc", "device": str(recording), "flush_frames": 1}))
    devices = open_rig_devices(rig, open_display=False)
    try:
        assert devices.camera.calibration is rig.camera
        assert [_index(devices.camera.capture()) for _ in range(2)] == [1, 3]
    finally:
        devices.close()
    bad = {"device": ("/dev/video0", -1, "devices.camera.device: must be a device path"),
           "format": ("MJPEG", "mjpeg", "devices.camera.format: must be one of MJPEG, YUYV, found 'mjpeg'"),
           "flush_frames": (4, 40, "devices.camera.flush_frames: must be a whole number of frames 0..32"),
           "reconnect_timeout_s": (10, "10", "devices.camera.reconnect_timeout_s: must be a number")}
    for field, (_, value, message) in bad.items():
        with pytest.raises(ConfigError, match=message):
            open_rig_devices(load_rig(_rig_file(tmp_path, {"type": "uvc", field: value})), open_display=False)


def test_a_lost_camera_is_disconnected_and_comes_back_with_the_same_frames(recording, tmp_path):
    """The device lost: its node removed and its stream ended (OpenCV's capture released, as the kernel ends a
    stream whose device is gone); reconnect waits for the node and opens it again."""
    from rangekit.drivers.uvc.camera import UvcCamera

    cam = UvcCamera(str(recording), size=(W, H), flush_frames=0)
    first = [cam.capture() for _ in range(2)]
    away = tmp_path / "unplugged.avi"
    os.rename(recording, away)
    cam._cap.release()
    with pytest.raises(DeviceDisconnected) as exc:
        cam.capture()
    assert str(exc.value) == (f"uvc {recording}: lost while reading a frame (the device node is gone); check its USB "
                              "cable and power (was it unplugged?)")
    with pytest.raises(DeviceDisconnected, match="the recording is gone"):
        cam.reconnect(0.2)
    os.rename(away, recording)
    cam.reconnect(2.0)
    again = [cam.capture() for _ in range(2)]
    cam.close()
    assert all(np.array_equal(a, b) for a, b in zip(first, again))     # replayed byte-identical


def test_the_live_page_streams_a_uvc_camera(recording, tmp_path):
    """The web app's Live page takes its frames from RigHolder.grab (rangekit.ui.stream) and draws them with
    live_frame: a uvc camera of a hardware rig file, here on the recording."""
    from rangekit.ui.live import live_frame
    from rangekit.ui.rig_holder import RigHolder

    holder = RigHolder.hardware(_rig_file(tmp_path, {"type": "uvc", "device": str(recording), "flush_frames": 0}))
    try:
        assert holder.fault is None, holder.fault
        frames = [holder.grab() for _ in range(2)]
        shown = live_frame(frames[1], holder.full_scale, 1)
    finally:
        holder.close()
    assert [_index(f) for f in frames] == [0, 1]
    assert shown is not None
