"""The rig file's camera controls (:class:`rangekit.rig.camera_controls.CameraControls`) as depthai v3 commands.

A depthai ``CameraControl`` message carries the commands; :class:`~rangekit.drivers.depthai.camera.
DepthaiCamera` fills the camera node's ``initialControl`` with them before the pipeline starts, and
sends a fresh message through ``Camera.inputControl.createInputQueue()`` when they change later
(``set_controls``). The mapping, one field at a time (docs/hardware.md):

==========================  ================================================================================
``exposure_us``, ``iso``    ``setManualExposure(round(exposure_us), iso)`` (microseconds, ISO 100..1600);
                            ``"auto"`` exposure: ``setAutoExposureEnable()`` and, with an ISO number,
                            ``setAutoExposureMaxISO(iso)`` (auto-exposure's gain stops there). A number of
                            microseconds with ``"iso": "auto"`` is refused: depthai has no shutter priority
``white_balance_k``         ``setAutoWhiteBalanceMode(OFF)`` + ``setManualWhiteBalance(K)``; ``"auto"``:
                            ``setAutoWhiteBalanceMode(AUTO)``; ``"mono"``: ``setAutoWhiteBalanceLock(True)``
                            (grey frames; a colour sensor keeps the balance it has)
``focus``, ``lock_focus``   a lens position: ``setAutoFocusMode(OFF)`` + ``setManualFocus(focus)``;
                            ``"auto"`` with ``lock_focus``: ``setAutoFocusMode(AUTO)`` + ``setAutoFocusTrigger()``
                            (focus once, then hold); ``"auto"`` without: ``setAutoFocusMode(CONTINUOUS_VIDEO)``
``fps``                     at pipeline build only: ``Camera.build(socket, sensorFps=fps)`` and
                            ``requestOutput(..., fps=fps)``; ``set_controls`` refuses another rate
==========================  ================================================================================

A manual exposure longer than one frame period (``1e6 / fps`` us) cannot be applied (the sensor would
cut it or drop the rate) and is refused. Fixed-focus modules ignore the focus commands.
"""

from __future__ import annotations

from rangekit.rig.camera_controls import CameraControls
from rangekit.errors import DeviceError

__all__ = ["AUTO_CONTROLS", "CONTROL_NAMES", "apply_controls", "check_frame_period"]

#: Every control the camera chooses itself: what a camera opened without controls runs with.
AUTO_CONTROLS = CameraControls(exposure_us=None, iso=None, white_balance_k=None, focus=None, lock_focus=False)

#: The depthai attribute paths used here (tests check them against the installed depthai).
CONTROL_NAMES = [
    "CameraControl", "CameraControl.setManualExposure", "CameraControl.setAutoExposureEnable",
    "CameraControl.setAutoExposureMaxISO", "CameraControl.setManualWhiteBalance",
    "CameraControl.setAutoWhiteBalanceMode", "CameraControl.setAutoWhiteBalanceLock",
    "CameraControl.AutoWhiteBalanceMode.OFF", "CameraControl.AutoWhiteBalanceMode.AUTO",
    "CameraControl.setManualFocus", "CameraControl.setAutoFocusMode", "CameraControl.setAutoFocusTrigger",
    "CameraControl.AutoFocusMode.OFF", "CameraControl.AutoFocusMode.AUTO",
    "CameraControl.AutoFocusMode.CONTINUOUS_VIDEO", "node.Camera.inputControl", "Node.Input.createInputQueue",
    "InputQueue.send",
]


def check_frame_period(controls: CameraControls, *, name: str) -> None:
    """Refuse a manual exposure longer than a frame period at ``controls.fps`` (DeviceError naming it)."""
    if controls.exposure_us is not None and controls.exposure_us > 1e6 / controls.fps * (1 + 1e-6):
        raise DeviceError(f"{name}: capture.camera.exposure_us {controls.exposure_us:g} us is longer than a frame "
                          f"at capture.camera.fps {controls.fps:g} ({1e6 / controls.fps:.0f} us); lower the "
                          "exposure or the frame rate")


def apply_controls(ctrl, controls: CameraControls, dai, *, name: str) -> None:
    """Write ``controls`` (all but ``fps``) into the depthai ``CameraControl`` ``ctrl``, in the order
    exposure, white balance, focus. ``name`` (the device) prefixes a DeviceError for a combination the
    device cannot apply."""
    check_frame_period(controls, name=name)
    if controls.exposure_us is not None:
        if controls.iso is None:
            raise DeviceError(f"{name}: capture.camera.iso 'auto' with a manual exposure_us is not possible on a "
                              "depthai camera (no shutter-priority mode); give an ISO 100..1600, or 'auto' "
                              "exposure too")
        ctrl.setManualExposure(int(round(controls.exposure_us)), int(controls.iso))
    else:
        ctrl.setAutoExposureEnable()
        if controls.iso is not None:
            ctrl.setAutoExposureMaxISO(int(controls.iso))
    awb = dai.CameraControl.AutoWhiteBalanceMode
    if controls.mono:
        ctrl.setAutoWhiteBalanceLock(True)
    elif controls.white_balance_k is None:
        ctrl.setAutoWhiteBalanceMode(awb.AUTO)
    else:
        ctrl.setAutoWhiteBalanceMode(awb.OFF)
        ctrl.setManualWhiteBalance(int(controls.white_balance_k))
    af = dai.CameraControl.AutoFocusMode
    if controls.focus is not None:
        ctrl.setAutoFocusMode(af.OFF)
        ctrl.setManualFocus(int(controls.focus))
    elif controls.lock_focus:
        ctrl.setAutoFocusMode(af.AUTO)
        ctrl.setAutoFocusTrigger()
    else:
        ctrl.setAutoFocusMode(af.CONTINUOUS_VIDEO)
