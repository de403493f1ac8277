"""One fake ``depthai`` module (tests only), at the API boundary the drivers use (depthai v3): put in
``sys.modules`` before a driver imports depthai, it records every call the driver makes on it, so a test reads
exactly which commands a real OAK camera would receive. The names it offers are checked against the installed
depthai by tests/drivers/test_depthai_driver.py (``DEPTHAI_NAMES``, ``DEPTHAI_STEREO_NAMES``).

:class:`FakeDepthai` holds what every test needs: the module object; the enums (:data:`SOCKETS`, the frame types,
the resize mode, the device states, the camera controls' modes, each member an object of its own with its
``name``); the device search, the device and its calibration; the pipeline and its node graph (``Camera``,
``StereoDepth``, ``Sync``, outputs linked to inputs, every node in ``created``); queues; frames; and the recorder
of calls, ``log``: ``(who, method, args)`` tuples. What a test's device does beyond that is a small subclass
overriding the hooks: :meth:`~FakeDepthai.answers` (does a search find it), :meth:`~FakeDepthai.calibration`,
:meth:`~FakeDepthai.opened` (a device just opened), :meth:`~FakeDepthai.message` (what a queue's ``get``
returns: by default a black frame of the output's size), :meth:`~FakeDepthai.check` (before a queue is used:
raise as a device that went away) and :meth:`~FakeDepthai.dot_projector`.
"""

from __future__ import annotations

import datetime
import sys
import time
import types

import numpy as np

__all__ = ["Named", "enum", "SOCKETS", "Recorder", "Frame", "FakeDepthai"]


class Named:
    """An enum member: an object of its own (equal only to itself), with its ``name``."""

    def __init__(self, name: str):
        self.name = name

    def __repr__(self):
        return self.name


def enum(*names) -> types.SimpleNamespace:
    """An enum of ``names``, each a :class:`Named`."""
    return types.SimpleNamespace(**{n: Named(n) for n in names})


#: ``CameraBoardSocket``: the same members in every fake module, so a test can name them before one is made.
SOCKETS = enum(*(f"CAM_{c}" for c in "ABCDEFGH"))


class Recorder:
    """Records every ``set*`` call as ``(owner, method, args)`` in the shared ``log``; each returns the recorder
    (depthai's setters chain)."""

    def __init__(self, log: list, owner: str):
        self._log, self._owner = log, owner

    def __getattr__(self, name):
        if not name.startswith("set"):
            raise AttributeError(name)

        def call(*args, **kwargs):
            self._log.append((self._owner, name, args))
            return self
        return call


class Frame:
    """An ``ImgFrame``: ``image`` (H, W) or (H, W, 3), handed out flat as depthai's ``getFrame`` does; its
    sequence number and its timestamp (the host clock when it was made)."""

    def __init__(self, image: np.ndarray, seq: int = 0):
        self.image, self.seq, self.t = image, seq, datetime.timedelta(seconds=time.monotonic())

    def getWidth(self):
        return self.image.shape[1]

    def getHeight(self):
        return self.image.shape[0]

    def getFrame(self):
        return self.image.reshape(-1)

    def getTimestamp(self, offset=None):
        return self.t

    def getSequenceNum(self):
        return self.seq


class FakeDepthai:
    """The fake depthai: ``module`` (install it with :meth:`install`), ``log`` (the calls), ``created`` (the
    pipeline's nodes, in order). ``sockets``: the cameras the device has; ``mxid``: its id."""

    mxid = "FAKE-MXID"

    def __init__(self, log: list | None = None, *, sockets=("CAM_A", "CAM_B", "CAM_C")):
        self.log = [] if log is None else log
        self.sockets, self.created = tuple(sockets), []
        self.module = self._module()

    def install(self, monkeypatch) -> types.ModuleType:
        """Put the module in ``sys.modules`` as ``depthai`` for one test; returns it."""
        monkeypatch.setitem(sys.modules, "depthai", self.module)
        return self.module

    # ------------------------------------------------------------------------- the hooks
    def answers(self) -> bool:
        """Whether a device search finds the device."""
        return True

    def calibration(self):
        """What ``Device.readCalibration()`` returns (None: no calibration handler)."""
        return None

    def opened(self, device) -> None:
        """Called as ``device`` opens."""

    def check(self, queue) -> None:
        """Called before ``queue`` is read or sent to: raise as depthai raises when the device went away."""

    def message(self, queue):
        """What ``queue.get()`` returns: a black frame of its output's size."""
        return Frame(np.zeros(queue.output.shape, np.uint8))

    def dot_projector(self, intensity: float) -> bool:
        """What ``setIrLaserDotProjectorIntensity`` returns: whether the device has a dot projector."""
        return True

    # ------------------------------------------------------------------------- the module
    def _module(self) -> types.ModuleType:
        fake, log = self, self.log
        dai = types.ModuleType("depthai")
        dai.fake = fake
        dai.CameraBoardSocket = SOCKETS
        dai.XLinkDeviceState = enum("X_LINK_BOOTED", "X_LINK_UNBOOTED")
        dai.ImgFrame = types.SimpleNamespace(Type=enum("RGB888i", "GRAY8"))
        dai.ImgResizeMode, dai.CameraExposureOffset = enum("CROP"), enum("START")
        dai.CameraModel, dai.LengthUnit = enum("Perspective"), enum("METER")
        dai.Clock = types.SimpleNamespace(now=lambda: datetime.timedelta(seconds=time.monotonic()))
        dai.MessageQueue = types.SimpleNamespace(QueueException=type("QueueException", (RuntimeError,), {}))

        class CameraControl(Recorder):
            AutoWhiteBalanceMode = enum("OFF", "AUTO")
            AutoFocusMode = enum("OFF", "AUTO", "CONTINUOUS_VIDEO")

            def __init__(self):
                super().__init__(log, "control")
        dai.CameraControl = CameraControl

        class Info:
            name, state = "1.1", dai.XLinkDeviceState.X_LINK_UNBOOTED

            def getDeviceId(self):
                return fake.mxid

        def search(timeoutMs=0):
            log.append(("xlink", "getAllConnectedDevices", (timeoutMs,)))
            return [Info()] if fake.answers() else []
        dai.XLinkConnection = types.SimpleNamespace(getAllConnectedDevices=search)

        class Device:
            def __init__(self, info):
                log.append(("device", "open", (info.getDeviceId(),)))
                fake.opened(self)

            def getDeviceId(self):
                return fake.mxid

            def getConnectedCameras(self):
                return [getattr(SOCKETS, s) for s in fake.sockets]

            def readCalibration(self):
                return fake.calibration()

            def setIrLaserDotProjectorIntensity(self, x, mask=-1):
                log.append(("device", "setIrLaserDotProjectorIntensity", (x,)))
                return fake.dot_projector(x)

            def setIrFloodLightIntensity(self, x, mask=-1):
                log.append(("device", "setIrFloodLightIntensity", (x,)))
                return True

            def close(self):
                log.append(("device", "close", ()))
        dai.Device = Device

        class Queue:
            def __init__(self, node, output=None):
                self.node, self.output, self.n = node, output, 0

            @property
            def device(self):
                return self.node.pipeline.device

            def get(self, timeout=None):
                fake.check(self)
                self.n += 1
                return fake.message(self)

            def send(self, msg):
                fake.check(self)
                log.append(("inputControl", "send", (msg,)))

        class Output:
            def __init__(self, node, kind: str, shape=None, size=None, frame_type=None):
                self.node, self.kind, self.shape, self.size, self.frame_type, self.links = \
                    node, kind, shape, size, frame_type, []

            def link(self, inp) -> None:
                self.links.append(inp)
                inp.source = self

            def createOutputQueue(self, maxSize=4, blocking=False):
                return Queue(self.node, self)

        class Input:
            def __init__(self, name: str):
                self.name, self.source = name, None

        class Inputs(dict):
            def __missing__(self, name):
                self[name] = Input(name)
                return self[name]

        class Node:
            def __init__(self, pipeline):
                self.pipeline = pipeline
                fake.created.append(self)

        class Camera(Node):
            def build(self, socket, sensorFps=None):
                log.append(("Camera", "build", (socket.name, sensorFps)))
                self.socket = socket
                self.initialControl = Recorder(log, f"initialControl {socket.name}")
                self.inputControl = types.SimpleNamespace(createInputQueue=lambda: Queue(self))
                return self

            def requestOutput(self, size, kind, mode, fps=None):
                log.append(("Camera", "requestOutput", (tuple(size), kind.name, mode.name, fps)))
                shape = (size[1], size[0]) if kind.name == "GRAY8" else (size[1], size[0], 3)
                return Output(self, "camera", shape, tuple(size), kind)

            def requestFullResolutionOutput(self):
                return Output(self, "camera", (800, 1280))

        class StereoDepth(Node):
            PresetMode = enum("DEFAULT")

            def build(self, *args):
                log.append(("StereoDepth", "build", ()))
                self.sources, self.depth = args[:2], Output(self, "depth", (800, 1280))
                return self

            def setLeftRightCheck(self, on):
                self.lr_check = on

            def setDepthAlign(self, socket):
                self.align = socket

            def setOutputSize(self, w, h):
                self.size = (w, h)

        class Sync(Node):
            def __init__(self, pipeline):
                super().__init__(pipeline)
                self.inputs, self.out, self.threshold = Inputs(), Output(self, "sync"), None

            def setSyncThreshold(self, td):
                self.threshold = td
        dai.node = types.SimpleNamespace(Camera=Camera, StereoDepth=StereoDepth, Sync=Sync)

        class Pipeline:
            def __init__(self, device):
                self.device, self.running = device, False

            def create(self, kind):
                return kind(self)

            def start(self):
                log.append(("Pipeline", "start", ()))
                self.running = True

            def isRunning(self):
                return self.running

            def stop(self):
                log.append(("Pipeline", "stop", ()))
                self.running = False
        dai.Pipeline = Pipeline
        return dai
