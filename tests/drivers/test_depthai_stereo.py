"""``rangekit stereo --device`` against a fake ``depthai`` module at the API boundary.

The fake records every node, link and emitter call and streams a simulated OAK-D-Pro-like pair
(:func:`rangekit.sim.sensors.stereo.render_stereo`, 320 x 200) through a Sync node's message groups, with the
simulator's true depth as the "device's StereoDepth". So the tests check the pipeline the driver builds
(synchronised left/right mono frames, dot projector and flood as asked, StereoDepth only with
--on-device) and that the matcher's depth of the captured pair agrees with the truth.
"""

from __future__ import annotations

import enum
import sys
import types

import numpy as np
import pytest

from rangekit.cli.run import main

W, H = 320, 200


class _Socket(enum.Enum):
    CAM_A = 0
    CAM_B = 1
    CAM_C = 2
    CAM_D = 3


class _Output:
    def __init__(self, node, kind: str, size=None, frame_type=None):
        self.node, self.kind, self.size, self.frame_type, self.links = node, kind, size, frame_type, []

    def link(self, inp) -> None:
        self.links.append(inp)
        inp.source = self

    def createOutputQueue(self, maxSize=4, blocking=False):
        return _Queue(self)


class _Input:
    def __init__(self, name: str):
        self.name, self.source = name, None


class _Frame:
    def __init__(self, data: np.ndarray, seq: int):
        self.data, self.seq = data, seq

    def getFrame(self):
        return self.data

    def getWidth(self):
        return self.data.shape[1]

    def getHeight(self):
        return self.data.shape[0]

    def getSequenceNum(self):
        return self.seq


class _Queue:
    """Sync groups: {input name: frame}; the 4th group's right frame is one sequence number off."""

    def __init__(self, output: _Output):
        self.output, self.n = output, 0

    def get(self, timeout=None):
        dai = self.output.node.pipeline.dai
        sync = self.output.node
        assert isinstance(sync, dai.node.Sync), "frames are read from the Sync node's output"
        self.n += 1
        group = {}
        for name, inp in sync.inputs.items():
            src = inp.source
            if src.kind == "camera":
                img = dai.truth.left if src.node.socket == _Socket.CAM_B else dai.truth.right
                seq = self.n + (1 if self.n == 4 and src.node.socket == _Socket.CAM_C else 0)
                group[name] = _Frame(img, seq)
            else:
                mm = np.where(dai.truth.hit, np.rint(dai.truth.depth * 1000.0), 0).astype(np.uint16)
                group[name] = _Frame(mm, self.n)
        dai.calls.append(("get", self.n))
        return group


def _fake_depthai(truth, rig, *, dot_projector: bool = True):
    dai = types.ModuleType("depthai")
    dai.truth, dai.calls, dai.created = truth, [], []
    dai.CameraBoardSocket = _Socket
    dai.CameraModel = types.SimpleNamespace(Perspective="perspective")
    dai.LengthUnit = types.SimpleNamespace(METER="m")
    dai.ImgFrame = types.SimpleNamespace(Type=types.SimpleNamespace(GRAY8="GRAY8", RGB888i="RGB888i"))
    dai.ImgResizeMode = types.SimpleNamespace(CROP="CROP")
    dai.XLinkDeviceState = types.SimpleNamespace(X_LINK_BOOTED="booted", X_LINK_UNBOOTED="unbooted")
    dai.MessageQueue = types.SimpleNamespace(QueueException=type("QueueException", (Exception,), {}))
    info = types.SimpleNamespace(name="1.1", state="unbooted", getDeviceId=lambda: "FAKE-OAK-D-PRO")
    dai.XLinkConnection = types.SimpleNamespace(getAllConnectedDevices=lambda timeoutMs=0: [info])
    cams = {_Socket.CAM_B: rig.cameras[0], _Socket.CAM_C: rig.cameras[1]}

    class Handler:
        def hasCameraCalibration(self, s):
            return s in cams

        def getDistortionModel(self, s):
            return "perspective"

        def getDefaultIntrinsics(self, s):
            c = cams[s]
            return c.K.tolist(), c.width, c.height

        def getDistortionCoefficients(self, s):
            return list(cams[s].dist) + [0.0] * (14 - len(cams[s].dist))

        def getCameraExtrinsics(self, src, dst, unit=None):
            assert unit == "m"
            return (np.linalg.inv(cams[dst].T_world_cam) @ cams[src].T_world_cam).tolist()   # T_dst_src

    class Device:
        def __init__(self, found):
            dai.calls.append(("open", found.getDeviceId()))

        def getDeviceId(self):
            return "FAKE-OAK-D-PRO"

        def getConnectedCameras(self):
            return [_Socket.CAM_A, _Socket.CAM_B, _Socket.CAM_C]

        def readCalibration(self):
            return Handler()

        def setIrLaserDotProjectorIntensity(self, x, mask=-1):
            dai.calls.append(("dots", x))
            return dot_projector

        def setIrFloodLightIntensity(self, x, mask=-1):
            dai.calls.append(("flood", x))
            return True

        def close(self):
            dai.calls.append(("close",))

    class Node:
        def __init__(self, pipeline):
            self.pipeline = pipeline
            dai.created.append(self)

    class Camera(Node):
        def build(self, socket):
            self.socket = socket
            return self

        def requestOutput(self, size, frame_type, mode):
            assert mode == "CROP"
            return _Output(self, "camera", tuple(size), frame_type)

    class Inputs(dict):
        def __missing__(self, name):
            self[name] = _Input(name)
            return self[name]

    class Sync(Node):
        def __init__(self, pipeline):
            super().__init__(pipeline)
            self.inputs, self.out, self.threshold = Inputs(), _Output(self, "sync"), None

        def setSyncThreshold(self, td):
            self.threshold = td

    class StereoDepth(Node):
        PresetMode = types.SimpleNamespace(DEFAULT="default")

        def build(self, left, right, preset):
            self.sources, self.depth = (left, right), _Output(self, "depth")
            return self

        def setLeftRightCheck(self, on):
            self.lr_check = on

        def setDepthAlign(self, socket):
            self.align = socket

        def setOutputSize(self, w, h):
            self.size = (w, h)

    class Pipeline:
        def __init__(self, device):
            self.dai, self.running = dai, False

        def create(self, cls):
            return cls(self)

        def start(self):
            self.running = True
            dai.calls.append(("start",))

        def isRunning(self):
            return self.running

        def stop(self):
            self.running = False
            dai.calls.append(("stop",))

    dai.Device, dai.Pipeline = Device, Pipeline
    dai.node = types.SimpleNamespace(Camera=Camera, Sync=Sync, StereoDepth=StereoDepth)
    return dai


@pytest.fixture(scope="module")
def sim_pair():
    from rangekit.sim.sensors.stereo import render_stereo, stereo_rig, stereo_scene

    rig = stereo_rig(W, H)
    return rig, render_stereo(stereo_scene(), rig, dots=True, seed=0)


@pytest.fixture
def fake(sim_pair, monkeypatch):
    rig, cap = sim_pair
    dai = _fake_depthai(cap, rig)
    monkeypatch.setitem(sys.modules, "depthai", dai)
    return dai


def _nodes(dai, kind: str):
    return [n for n in dai.created if type(n).__name__ == kind]


def _depth_error(depth, cap):
    m = cap.visible.copy()
    m[:8], m[-8:], m[:, :8], m[:, -8:] = False, False, False, False
    ok = m & np.isfinite(depth)
    return ok.sum() / m.sum(), float(np.median(np.abs(depth[ok] - cap.depth[ok])))


def test_stereo_device_asks_for_synchronised_frames_sets_the_emitters_and_matches(fake, sim_pair, tmp_path, capsys):
    rig, cap = sim_pair
    out = tmp_path / "live"
    assert main(["stereo", "--device", "--dots", "0.6", "--size", f"{W}x{H}", "--out", str(out)]) == 0
    cams = _nodes(fake, "Camera")
    assert sorted(c.socket.name for c in cams) == ["CAM_B", "CAM_C"]
    (sync,) = _nodes(fake, "Sync")
    assert set(sync.inputs) == {"left", "right"}
    assert {sync.inputs["left"].source.node.socket, sync.inputs["right"].source.node.socket} == \
        {_Socket.CAM_B, _Socket.CAM_C} and sync.inputs["left"].source.node.socket == _Socket.CAM_B
    assert all(sync.inputs[k].source.frame_type == "GRAY8" and sync.inputs[k].source.size == (W, H)
               for k in ("left", "right"))
    assert _nodes(fake, "StereoDepth") == []                     # not started without --on-device
    calls = fake.calls
    assert calls.index(("dots", 0.6)) < calls.index(("start",)) and ("flood", 0.0) in calls
    assert calls[-2:] == [("dots", 0.0), ("close",)] and ("stop",) in calls
    # 3 groups dropped while the emitters settle, the 4th has mismatched sequence numbers: the 5th is used
    assert [c for c in calls if c[0] == "get"][-1] == ("get", 5)
    depth = np.load(out / "depth.npy")
    cover, err = _depth_error(depth, cap)
    assert cover > 0.85 and err < 0.01, (cover, err)
    for name in ("left.png", "right.png", "rig.json", "depth.png", "cloud.ply"):
        assert (out / name).exists()
    assert not (out / "device_depth.npy").exists()
    text = capsys.readouterr().out
    assert "dot projector 0.6, flood 0" in text and "frame 5" in text


def test_on_device_starts_stereodepth_and_compares(fake, sim_pair, tmp_path, capsys):
    rig, cap = sim_pair
    out = tmp_path / "live"
    assert main(["stereo", "--device", "--on-device", "--size", f"{W}x{H}", "--out", str(out)]) == 0
    (stereo,) = _nodes(fake, "StereoDepth")
    (sync,) = _nodes(fake, "Sync")
    assert [s.node.socket for s in stereo.sources] == [_Socket.CAM_B, _Socket.CAM_C]
    assert stereo.align == _Socket.CAM_B and stereo.size == (W, H)
    assert sync.inputs["depth"].source is stereo.depth             # the device's depth is in the same group
    assert ("dots", 0.8) in fake.calls and ("flood", 0.0) in fake.calls
    dev = np.load(out / "device_depth.npy")
    np.testing.assert_allclose(dev[cap.hit], cap.depth[cap.hit], atol=6e-4)   # mm quantisation
    text = capsys.readouterr().out
    assert "ours vs the device's StereoDepth" in text


def test_the_comparison_summary_against_a_known_offset():
    from rangekit.app.commands.stereo_live import compare_depths

    a = np.full((4, 5), 1.0)
    b = a - 0.002
    b[0, 0] = np.nan
    a[1, 1] = np.nan
    c = compare_depths(a, b)
    assert c.n_both == 18 and c.ours_fraction == 19 / 20 and c.device_fraction == 19 / 20
    assert abs(c.median_m - 0.002) < 1e-12 and abs(c.rms_m - 0.002) < 1e-12


def test_no_dot_projector_is_a_device_error(sim_pair, monkeypatch, tmp_path, capsys):
    rig, cap = sim_pair
    dai = _fake_depthai(cap, rig, dot_projector=False)
    monkeypatch.setitem(sys.modules, "depthai", dai)
    assert main(["stereo", "--device", "--size", f"{W}x{H}", "--out", str(tmp_path / "o")]) == 1
    assert "--dots 0" in capsys.readouterr().err
    assert ("start",) not in dai.calls and dai.calls[-1] == ("close",)
    assert main(["stereo", "--device", "--dots", "0", "--size", f"{W}x{H}", "--out", str(tmp_path / "o")]) == 0


@pytest.mark.parametrize("argv, expected", [
    (["stereo", "--device", "l.png", "r.png", "--out", "o"], "drop LEFT, RIGHT"),
    (["stereo", "l.png", "r.png", "--rig", "rig.json", "--dots", "0.5", "--out", "o"], "--dots: only with --device"),
    (["stereo", "--device", "--dots", "1.5", "--out", "o"], "--dots"),
    (["stereo", "l.png", "--out", "o"], "missing RIGHT, --rig"),
])
def test_bad_options_are_usage_errors(argv, expected, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    try:
        code = main(argv)
    except SystemExit as exc:                 # argparse refuses an option type's value itself
        code = exc.code
    assert code == 2
    assert expected in capsys.readouterr().err


def test_every_depthai_stereo_name_exists():
    dai = pytest.importorskip("depthai")
    from rangekit.drivers.depthai.stereo import DEPTHAI_STEREO_NAMES

    from depthai_names import missing_names

    missing = missing_names(dai, DEPTHAI_STEREO_NAMES)
    assert not missing, f"depthai {dai.__version__} lacks {missing}"


@pytest.mark.hardware
def test_live_pair_from_a_real_device_or_skip(tmp_path):
    pytest.importorskip("depthai")
    from rangekit.drivers.depthai.stereo import capture_stereo_pair
    from rangekit.errors import DeviceError

    try:
        pair = capture_stereo_pair(search_timeout_s=0.5, on_device=True)
    except DeviceError as exc:
        pytest.skip(f"no depthai stereo device answered: {exc}")
    assert pair.left.shape == pair.right.shape == (400, 640) and pair.left.dtype == np.uint8
    assert pair.right_camera.T_world_cam[0, 3] < 0 or pair.right_camera.T_world_cam[0, 3] > 0
    assert pair.device_depth is not None and pair.device_depth.shape == (400, 640)
