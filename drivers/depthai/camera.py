"""Luxonis OAK cameras through depthai v3: colour/mono frames, on-device stereo depth, calibration.

depthai is imported inside the functions and methods that need it, never at module level: importing it
takes over a second, and opening a device searches for one (10 s by default). ``import
rangekit.drivers.depthai.camera`` is therefore cheap and works without depthai.

Conventions at this boundary (see ARCHITECTURE.md):

- Lengths in metres. depthai depth frames are uint16 millimetres (0 = invalid) and its extrinsics are
  centimetres unless ``LengthUnit.METER`` is passed; both are converted here.
- Images RGB (``ImgFrame.Type.RGB888i``, read with ``getFrame()``; ``getCvFrame()`` would give BGR).
- Poses ``T_a_b`` with ``p_a = T_a_b @ p_b``. depthai's ``getCameraExtrinsics(src, dst)`` is the
  transform that maps points in ``src``'s frame into ``dst``'s (``T_dst_src``; e.g. left -> right on an
  OAK-D has translation (-7.5, 0, 0) cm), so ``T_world_cam = getCameraExtrinsics(cam, first_cam)``.
- Pixels: the centre of the top-left pixel is (0, 0). Intrinsics for a requested output size are
  derived from the calibrated ones (``getDefaultIntrinsics``) by :func:`scale_intrinsics`, which keeps
  pixel centres (``c' = (c + 0.5) s - 0.5``) and models ``ImgResizeMode.CROP`` (scale so the output is
  covered, crop the centre). depthai's own ``getCameraIntrinsics(socket, w, h)`` scales ``c' = c s``,
  i.e. treats pixel corners as the origin; the two differ by ``(s - 1) / 2`` px (0.25 px at half size).
"""

from __future__ import annotations

import datetime
import time

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.rig.camera_controls import CameraControls, require_locked
from rangekit.drivers.depthai.controls import AUTO_CONTROLS, CONTROL_NAMES, apply_controls, check_frame_period
from rangekit.drivers.discovery import open_depthai_device
from rangekit.errors import ConfigError, DeviceDisconnected, DeviceError, DeviceTimeout, one_line
from rangekit.rig.rig_file import Rig
from rangekit.rig.checks import DEFAULT_SEARCH_S, DEPTHAI_SOCKETS

__all__ = ["DepthaiCamera", "open_camera", "list_cameras", "DEPTHAI_NAMES", "calibration_to_rig", "pinhole_from_calibration",
           "scale_intrinsics", "SOCKETS"]

SOCKETS = DEPTHAI_SOCKETS
#: What a lost or silent camera's message says to check.
_CHECK = "check its USB/PoE cable and power (was it unplugged or reset?)"

#: Every depthai attribute path this module uses; tests check each against the installed depthai.
DEPTHAI_NAMES = [
    "Pipeline", "Pipeline.create", "Pipeline.start", "Pipeline.stop", "Pipeline.isRunning",
    "node.Camera", "node.Camera.build", "node.Camera.requestOutput", "node.Camera.requestFullResolutionOutput",
    "node.Camera.initialControl", *CONTROL_NAMES,
    "node.StereoDepth", "node.StereoDepth.build", "node.StereoDepth.depth", "node.StereoDepth.setDepthAlign",
    "node.StereoDepth.setOutputSize", "node.StereoDepth.PresetMode.DEFAULT",
    "Node.Output.createOutputQueue", "MessageQueue.get", "MessageQueue.QueueException",
    "ImgFrame.Type.RGB888i", "ImgFrame.Type.GRAY8", "ImgFrame.getFrame", "ImgFrame.getWidth",
    "ImgFrame.getHeight", "ImgFrame.getTimestamp", "CameraExposureOffset.START", "ImgResizeMode.CROP",
    "Clock.now",
    "Device", "Device.close", "Device.readCalibration", "Device.getConnectedCameras", "Device.getDeviceId",
    "Device.setIrLaserDotProjectorIntensity", "Device.setIrFloodLightIntensity",
    "XLinkConnection.getAllConnectedDevices", "XLinkDeviceState.X_LINK_BOOTED",
    "DeviceInfo.getDeviceId", "DeviceInfo.name", "DeviceInfo.state", "DeviceInfo.protocol", "DeviceInfo.platform",
    "CalibrationHandler", "CalibrationHandler.getDefaultIntrinsics",
    "CalibrationHandler.getDistortionCoefficients", "CalibrationHandler.getDistortionModel",
    "CalibrationHandler.getCameraExtrinsics", "CalibrationHandler.hasCameraCalibration",
    "CameraModel.Perspective", "LengthUnit.METER",
    *(f"CameraBoardSocket.{s}" for s in SOCKETS),
]


# ----------------------------------------------------------------------------- pure calibration helpers
def _socket(dai, name: str):
    if name not in SOCKETS:
        raise ConfigError(f"depthai socket {name!r} is not one of {list(SOCKETS)}")
    return getattr(dai.CameraBoardSocket, name)


def scale_intrinsics(K: np.ndarray, calibrated_size: tuple[int, int],
                     size: tuple[int, int]) -> np.ndarray:
    """(3, 3) intrinsics for an output of ``size`` taken from a sensor calibrated at ``calibrated_size``.

    Models depthai's ``ImgResizeMode.CROP``: scale by ``s = max(w / W, h / H)`` so the output is covered,
    then crop the centre. Pixel centres are kept: ``c' = (c + 0.5) s - 0.5 - crop_offset``.
    """
    (W, H), (w, h) = calibrated_size, size
    s = max(w / W, h / H)
    ox, oy = (W * s - w) / 2.0, (H * s - h) / 2.0
    K = np.asarray(K, dtype=np.float64)
    out = np.array([[K[0, 0] * s, 0.0, (K[0, 2] + 0.5) * s - 0.5 - ox],
                    [0.0, K[1, 1] * s, (K[1, 2] + 0.5) * s - 0.5 - oy],
                    [0.0, 0.0, 1.0]])
    return out


def pinhole_from_calibration(handler, socket: str, size: tuple[int, int], *,
                             world_socket: str | None = None) -> PinholeCamera:
    """The :class:`PinholeCamera` of one depthai camera at an output ``size`` (width, height).

    Parameters
    ----------
    handler : depthai.CalibrationHandler
        From ``Device.readCalibration()`` or offline, ``depthai.CalibrationHandler("calib.json")``.
    socket : str
        "CAM_A" (usually colour), "CAM_B" (left), "CAM_C" (right), ...
    size : (width, height) of the frames the camera node outputs (``ImgResizeMode.CROP``).
    world_socket : str, optional
        Camera whose frame is the world; ``T_world_cam`` is identity when omitted or equal to ``socket``.

    Returns
    -------
    PinholeCamera named ``socket``; K rescaled by :func:`scale_intrinsics`, the 14 depthai
    distortion coefficients (OpenCV order k1 k2 p1 p2 k3 k4 k5 k6 s1 s2 s3 s4 tx ty), pose in metres.

    Raises
    ------
    ConfigError
        If the handler has no calibration for ``socket``, the lens model is not perspective, or the
        tilted-sensor terms tx, ty are non-zero (rangekit's lens model has no tilt).
    """
    import depthai as dai

    sock = _socket(dai, socket)
    where = f"depthai calibration of {socket}"
    if not handler.hasCameraCalibration(sock):
        raise ConfigError(f"{where}: not present in the calibration (calibrate this camera or pick another "
                          "socket)")
    model = handler.getDistortionModel(sock)
    if model != dai.CameraModel.Perspective:
        raise ConfigError(f"{where}: lens model {model.name} is not supported, expected Perspective")
    K0, W, H = handler.getDefaultIntrinsics(sock)
    w, h = (int(v) for v in size)
    K = scale_intrinsics(np.asarray(K0), (int(W), int(H)), (w, h))
    dist = np.asarray(handler.getDistortionCoefficients(sock), dtype=np.float64)
    if dist.size == 14 and np.any(dist[12:] != 0):
        raise ConfigError(f"{where}: tilted-sensor distortion tx, ty = {dist[12:].tolist()} is not supported "
                          "by rangekit's lens model; recalibrate without the tilted model")
    if dist.size not in (4, 5, 8, 12, 14):
        raise ConfigError(f"{where}: expected 4, 5, 8, 12 or 14 distortion coefficients, found {dist.size}")
    T = np.eye(4)
    if world_socket is not None and world_socket != socket:
        try:
            T = np.asarray(handler.getCameraExtrinsics(sock, _socket(dai, world_socket),
                                                       unit=dai.LengthUnit.METER), dtype=np.float64)
        except RuntimeError as exc:
            raise ConfigError(f"{where}: no extrinsics linking it to {world_socket}: {exc}") from exc
        # depthai stores rotations as float32: re-orthonormalise so PinholeCamera accepts them.
        U, _, Vt = np.linalg.svd(T[:3, :3])
        T[:3, :3] = U @ Vt
    return PinholeCamera(K, w, h, dist, T, socket)


def calibration_to_rig(handler, *, size: tuple[int, int], sockets: tuple[str, ...] = ("CAM_A",),
                       device_id: str | None = None, capture: dict | None = None) -> Rig:
    """A :class:`Rig` of depthai cameras, world = the first socket's camera frame (metres).

    ``size`` is the output size (width, height) used for every socket; ``device_id`` is recorded in
    ``rig.devices["depthai"]`` so the rig file says how to reach the camera.
    """
    if not sockets:
        raise ConfigError("calibration_to_rig: 'sockets' is empty; pass e.g. ('CAM_A',)")
    cams = tuple(pinhole_from_calibration(handler, s, size, world_socket=sockets[0]) for s in sockets)
    devices = {"depthai": {"device_id": device_id, "sockets": list(sockets), "size": list(size)}}
    return Rig(cameras=cams, devices=devices, capture=dict(capture or {}))


# ----------------------------------------------------------------------------- the device
class DepthaiCamera:
    """An OAK camera implementing :class:`rangekit.rig.devices.Camera`, plus IR emitters and stereo depth.

    Parameters
    ----------
    device_id : str, optional
        Device id (MXID), name or IP; the first device found when omitted.
    socket : str
        Camera to capture from: "CAM_A" (colour on OAK-D), "CAM_B", "CAM_C", ...
    size : (width, height) of captured frames; intrinsics are rescaled to it.
    controls : CameraControls, optional
        Exposure, ISO, white balance (``mono``: (H, W) uint8 grey frames instead of (H, W, 3) RGB), focus
        and frame rate (the rig file's ``capture.camera``; mapping: :mod:`rangekit.drivers.depthai.controls`),
        applied before the first frame; None: the camera's own automatic controls at 30 fps.
    coded_light : bool
        Opened for coded light: auto-exposure is refused (ConfigError) unless ``controls.allow_auto_exposure``.
    search_timeout_s : how long to look for the device (the rig file's ``devices.camera.search_timeout_s``).
    depth : bool
        Also run on-device ``StereoDepth`` (CAM_B/CAM_C, aligned to ``socket``) for :meth:`depth`, when
        the device has both cameras. Off by default: coded light needs no stereo, and it costs the
        device's bandwidth and the dot projector's attention.
    where : str
        Names the controls' origin (the rig file) in errors.

    Raises
    ------
    DeviceDisconnected if no device answers; DeviceError if it cannot be opened, lacks ``socket`` or cannot
    apply a control; ConfigError for auto-exposure with ``coded_light``.
    """

    def __init__(self, device_id: str | None = None, *, socket: str = "CAM_A", size: tuple[int, int] = (1280, 800),
                 controls: CameraControls | None = None, coded_light: bool = False,
                 search_timeout_s: float = DEFAULT_SEARCH_S, depth: bool = False, frame_timeout_s: float = 2.0,
                 where: str = "DepthaiCamera") -> None:
        import depthai as dai

        self._dai = dai
        self._socket_name = socket
        _socket(dai, socket)  # an unknown socket is refused before the search
        self.size = (int(size[0]), int(size[1]))
        self.controls = AUTO_CONTROLS if controls is None else controls
        self.mono = self.controls.mono
        self.coded_light, self._where = coded_light, where
        self.frame_timeout_s = frame_timeout_s
        if coded_light:
            require_locked(self.controls, where=where)
        check_frame_period(self.controls, name=where)
        self._want_depth = depth
        self._device = open_depthai_device(dai, device_id, search_timeout_s)
        self.device_id = self._device.getDeviceId()
        self._name = f"depthai {self.device_id} {socket}"
        self._start()

    def _start(self) -> None:
        """Build and start the pipeline on the opened device, with the controls in force (closes the device on
        failure)."""
        dai, sock, socket = self._dai, _socket(self._dai, self._socket_name), self._socket_name
        try:
            connected = set(self._device.getConnectedCameras())
            if sock not in connected:
                raise DeviceError(f"{self._name}: no camera on {socket}; this device has "
                                  f"{sorted(s.name for s in connected)}")
            self._handler = self._device.readCalibration()
            self._pipeline = dai.Pipeline(self._device)
            fps = float(self.controls.fps)
            cam = self._pipeline.create(dai.node.Camera).build(sock, sensorFps=fps)
            apply_controls(cam.initialControl, self.controls, dai, name=self._name)
            self._control = cam.inputControl.createInputQueue()
            kind = dai.ImgFrame.Type.GRAY8 if self.mono else dai.ImgFrame.Type.RGB888i
            out = cam.requestOutput(self.size, kind, dai.ImgResizeMode.CROP, fps=fps)
            self._frames = out.createOutputQueue(maxSize=4, blocking=False)
            self._depth = None
            stereo_socks = (dai.CameraBoardSocket.CAM_B, dai.CameraBoardSocket.CAM_C)
            if self._want_depth and all(s in connected for s in stereo_socks):
                left, right = (cam if s == sock else self._pipeline.create(dai.node.Camera).build(s, sensorFps=fps)
                               for s in stereo_socks)
                stereo = self._pipeline.create(dai.node.StereoDepth).build(
                    left.requestFullResolutionOutput(), right.requestFullResolutionOutput(),
                    dai.node.StereoDepth.PresetMode.DEFAULT)
                stereo.setDepthAlign(sock)
                stereo.setOutputSize(*self.size)
                self._depth = stereo.depth.createOutputQueue(maxSize=4, blocking=False)
            self._pipeline.start()
        except RuntimeError as exc:
            self._device.close()
            raise DeviceError(f"{self._name}: could not start the pipeline: {one_line(exc)}") from exc
        except (DeviceError, ConfigError):
            self._device.close()
            raise

    def reconnect(self, timeout_s: float) -> None:
        """Release the device and open it again (the same id), waiting up to ``timeout_s`` seconds for it to answer:
        after it was unplugged or reset mid-scan. The controls in force are applied again before the first frame.

        Raises DeviceDisconnected if it does not answer in time; DeviceError if it cannot be opened again."""
        try:
            self.close()
        except RuntimeError:    # the old connection is gone already
            pass
        self._device = open_depthai_device(self._dai, self.device_id, timeout_s)
        self._start()

    # ------------------------------------------------------------------ Camera protocol
    @property
    def calibration(self) -> PinholeCamera:
        """The capture camera at ``size``, from the device's EEPROM calibration; ``T_world_cam`` = I."""
        return pinhole_from_calibration(self._handler, self._socket_name, self.size)

    def calibration_handler(self):
        """The raw ``depthai.CalibrationHandler`` (save it with ``.eepromToJsonFile(path)``)."""
        return self._handler

    def capture(self) -> np.ndarray:
        """One frame whose exposure started after this call: (H, W, 3) RGB uint8, or (H, W) uint8 if mono.

        Raises DeviceTimeout if no such frame arrives within ``frame_timeout_s``.
        """
        frame = self._fresh(self._frames, "frame")
        w, h = frame.getWidth(), frame.getHeight()
        data = np.asarray(frame.getFrame())
        return data.reshape(h, w) if self.mono else data.reshape(h, w, 3)

    def set_controls(self, controls: CameraControls) -> None:
        """Apply exposure, ISO, white balance and focus now (one ``CameraControl`` message; frames exposed
        before it arrives keep the old settings). The frame rate and mono/colour are fixed when the camera
        is opened: a different ``fps`` or ``mono`` raises DeviceError; auto-exposure for coded light raises
        ConfigError unless allowed."""
        if self.coded_light:
            require_locked(controls, where=self._where)
        for field, now in (("fps", self.controls.fps), ("mono", self.controls.mono)):
            if getattr(controls, field) != now:
                raise DeviceError(f"{self._name}: capture.camera.{field} is set when the camera is opened "
                                  f"({now!r}), found {getattr(controls, field)!r}; reopen the camera to change it")
        ctrl = self._dai.CameraControl()
        apply_controls(ctrl, controls, self._dai, name=self._name)
        try:
            self._control.send(ctrl)
        except RuntimeError as exc:
            raise DeviceDisconnected(f"{self._name}: could not send the camera controls ({one_line(exc)}); "
                                     f"{_CHECK}") from exc
        self.controls = controls

    def depth(self) -> np.ndarray:
        """(H, W) float32 depth in metres along the optical axis of the capture camera, NaN where invalid.

        Computed on the device by StereoDepth from CAM_B/CAM_C and aligned to this camera's pixels.
        """
        if self._depth is None:
            raise DeviceError(f"{self._name}: stereo depth is not running (it needs CAM_B and CAM_C and "
                              "depth=True)")
        frame = self._fresh(self._depth, "depth frame")
        mm = np.asarray(frame.getFrame()).reshape(frame.getHeight(), frame.getWidth())
        out = mm.astype(np.float32) * np.float32(1e-3)
        out[mm == 0] = np.nan
        return out

    # ------------------------------------------------------------------ IR emitters
    def set_dot_projector(self, intensity: float) -> bool:
        """Dot projector power in [0, 1]; returns False if this model has none."""
        return bool(self._device.setIrLaserDotProjectorIntensity(float(np.clip(intensity, 0.0, 1.0))))

    def set_flood(self, intensity: float) -> bool:
        """IR flood light power in [0, 1]; returns False if this model has none."""
        return bool(self._device.setIrFloodLightIntensity(float(np.clip(intensity, 0.0, 1.0))))

    # ------------------------------------------------------------------ lifetime
    def close(self) -> None:
        """Stop the pipeline and release the device (idempotent)."""
        pipeline, self._pipeline = getattr(self, "_pipeline", None), None
        device, self._device = getattr(self, "_device", None), None
        try:
            if pipeline is not None and pipeline.isRunning():
                pipeline.stop()
        finally:
            if device is not None:
                device.close()

    def __enter__(self) -> "DepthaiCamera":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"DepthaiCamera({self.device_id!r}, socket={self._socket_name!r}, size={self.size})"

    # ------------------------------------------------------------------ helpers
    def _fresh(self, queue, what: str):
        """The first message on ``queue`` whose exposure started after now; older ones are dropped."""
        dai = self._dai
        t0 = dai.Clock.now()  # the host steady clock (CLOCK_MONOTONIC, as time.monotonic())
        deadline = time.monotonic() + self.frame_timeout_s
        while True:
            left = deadline - time.monotonic()
            if left <= 0:
                raise DeviceTimeout(f"{self._name}: no {what} exposed after the request within "
                                    f"{self.frame_timeout_s:.1f} s; {_CHECK}, and the frame rate")
            try:
                msg = queue.get(datetime.timedelta(seconds=left))
            except (RuntimeError, dai.MessageQueue.QueueException) as exc:
                raise DeviceDisconnected(f"{self._name}: lost while waiting for a {what} ({one_line(exc)}); "
                                         f"{_CHECK}") from exc
            if msg is None:
                continue
            try:
                ts = msg.getTimestamp(dai.CameraExposureOffset.START)
            except TypeError:  # depth frames may not take an offset
                ts = msg.getTimestamp()
            if ts >= t0:
                return msg


def open_camera(sec: dict, rig, *, coded_light: bool, where: str) -> DepthaiCamera:
    """An OAK camera of a checked ``devices.camera`` section (:mod:`rangekit.drivers.cameras`)."""
    from rangekit.rig.camera_controls import controls_from_capture

    return DepthaiCamera(sec.get("id"), socket=sec.get("socket", "CAM_A"), size=(rig.camera.width, rig.camera.height),
                         controls=controls_from_capture(rig.capture, where=where), coded_light=coded_light,
                         search_timeout_s=sec.get("search_timeout_s", DEFAULT_SEARCH_S), where=where)


def list_cameras(timeout_s: float = 1.0) -> list:
    """The OAK cameras that answer within ``timeout_s`` (:mod:`rangekit.drivers.cameras`)."""
    from rangekit.drivers.cameras import FoundCamera
    from rangekit.drivers.discovery import list_depthai_devices

    return [FoundCamera(c["device_id"], c["name"], f"{c['state']} {c['protocol']}")
            for c in list_depthai_devices(timeout_s=timeout_s)]
