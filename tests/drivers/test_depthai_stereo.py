"""``rangekit stereo --device`` against a fake ``depthai`` module at the API boundary.

The fake (tests/support/fake_depthai.py) records every node, link and emitter call and streams a simulated
OAK-D-Pro-like pair (:func:`rangekit.sim.sensors.stereo.render_stereo`, 320 x 200) through a Sync node's message
groups, with the simulator's true depth as the "device's StereoDepth". So the tests check the pipeline the driver builds
(synchronised left/right mono frames, dot projector and flood as asked, StereoDepth only with
--on-device) and that the matcher's depth of the captured pair agrees with the truth.
"""

from __future__ import annotations

import numpy as np
import pytest

from support.fake_depthai import SOCKETS as _Socket, FakeDepthai, Frame
from rangekit.cli.run import main

W, H = 320, 200


class _StereoDevice(FakeDepthai):
    """The fake depthai over a simulated pair (``truth``, the cameras of ``rig``): its calibration is the rig's two
    cameras, a Sync node's messages are groups {input name: frame} of the simulator's left and right images and true
    depth (the 4th group's right frame one sequence number off), and its dot projector is there or not."""

    mxid = "FAKE-OAK-D-PRO"
    SHORT = {("device", "open"): "open", ("device", "setIrLaserDotProjectorIntensity"): "dots",
             ("device", "setIrFloodLightIntensity"): "flood", ("device", "close"): "close",
             ("Pipeline", "start"): "start", ("Pipeline", "stop"): "stop", ("queue", "get"): "get"}

    def __init__(self, truth, rig, *, dot_projector: bool = True):
        self.truth, self.rig, self.has_dots = truth, rig, dot_projector
        super().__init__()

    @property
    def calls(self) -> list[tuple]:
        """The calls as these tests read them: ("open", id), ("dots", x), ("flood", x), ("start",), ("get", n),
        ("stop",), ("close",)."""
        return [(self.SHORT[who, method], *args) for who, method, args in self.log if (who, method) in self.SHORT]

    def dot_projector(self, intensity: float) -> bool:
        return self.has_dots

    def calibration(self):
        return _Handler(self.module, {_Socket.CAM_B: self.rig.cameras[0], _Socket.CAM_C: self.rig.cameras[1]})

    def message(self, queue):
        sync = queue.node
        assert isinstance(sync, self.module.node.Sync), "frames are read from the Sync node's output"
        group = {}
        for name, inp in sync.inputs.items():
            src = inp.source
            if src.kind == "camera":
                img = self.truth.left if src.node.socket == _Socket.CAM_B else self.truth.right
                seq = queue.n + (1 if queue.n == 4 and src.node.socket == _Socket.CAM_C else 0)
                group[name] = Frame(img, seq)
            else:
                mm = np.where(self.truth.hit, np.rint(self.truth.depth * 1000.0), 0).astype(np.uint16)
                group[name] = Frame(mm, queue.n)
        self.log.append(("queue", "get", (queue.n,)))
        return group


class _Handler:
    """The device's calibration: ``cams`` {socket: PinholeCamera}."""

    def __init__(self, dai, cams):
        self.dai, self.cams = dai, cams

    def hasCameraCalibration(self, s):
        return s in self.cams

    def getDistortionModel(self, s):
        return self.dai.CameraModel.Perspective

    def getDefaultIntrinsics(self, s):
        c = self.cams[s]
        return c.K.tolist(), c.width, c.height

    def getDistortionCoefficients(self, s):
        return list(self.cams[s].dist) + [0.0] * (14 - len(self.cams[s].dist))

    def getCameraExtrinsics(self, src, dst, unit=None):
        assert unit is self.dai.LengthUnit.METER
        return (np.linalg.inv(self.cams[dst].T_world_cam) @ self.cams[src].T_world_cam).tolist()   # T_dst_src


@pytest.fixture(scope="module")
def sim_pair():
    from rangekit.sim.sensors.stereo import render_stereo, stereo_rig, stereo_scene

    rig = stereo_rig(W, H)
    return rig, render_stereo(stereo_scene(), rig, dots=True, seed=0)


@pytest.fixture
def fake(sim_pair, monkeypatch):
    rig, cap = sim_pair
    dai = _StereoDevice(cap, rig)
    dai.install(monkeypatch)
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
    assert all(sync.inputs[k].source.frame_type.name == "GRAY8" and sync.inputs[k].source.size == (W, H)
               for k in ("left", "right"))
    assert {args[2] for who, method, args in fake.log if method == "requestOutput"} == {"CROP"}
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
    dai = _StereoDevice(cap, rig, dot_projector=False)
    dai.install(monkeypatch)
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

    from support.depthai_names import missing_names

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
