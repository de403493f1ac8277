"""A GenICam camera in a rig: the rig file's section, ``rangekit rig init --camera genicam`` then ``rangekit check
--rig`` on the genicam wheel's GenTL producer (a child process), the web app's Live page grabbing from it, and the
pixel formats made into frames (OpenCV's demosaicking on a known mosaic)."""

import json

import numpy as np
import pytest

from rangekit.errors import ConfigError


def _producer():
    pytest.importorskip("harvesters")
    from rangekit.drivers.genicam.producer import shipped_producer

    path = shipped_producer()
    if path is None:
        pytest.skip("the genicam wheel has no GenTL producer on this platform")
    return path


def _rig_file(tmp_path, producer: str, cli) -> str:
    """``rangekit rig init --camera genicam`` as a person edits it for the shipped producer: its 400x400 size, its
    producer and serial, no turntable or projector attached."""
    init = cli("rig", "init", "--camera", "genicam")
    assert init.code == 0, init.err
    rig = json.loads(init.out)
    assert rig["devices"]["camera"]["type"] == "genicam"
    rig["cameras"][0].update(width=400, height=400, K=[[500.0, 0.0, 199.5], [0.0, 500.0, 199.5], [0.0, 0.0, 1.0]])
    rig["devices"] = {"camera": {**rig["devices"]["camera"], "producer": producer, "serial": "1"}}
    path = tmp_path / "rig.json"
    path.write_text(json.dumps(rig))
    return str(path)


@pytest.mark.parametrize("field, value, says", [
    ("pixel_format", "Mono12p", "devices.camera.pixel_format: must be one of Mono8"),
    ("flush_frames", -1, "devices.camera.flush_frames: must be an integer 0..32"),
    ("trigger_activation", "Rising", "devices.camera.trigger_activation: must be one of RisingEdge"),
    ("serial", 1234, "devices.camera.serial: must be a non-empty string"),
    ("exposure", 1, "devices.camera.exposure: unknown field; a 'genicam' camera has only type, producer"),
])
def test_the_rig_file_section_is_checked_before_anything_opens(field, value, says):
    from rangekit.rig.checks import CAMERA_TEMPLATES, validate_devices

    validate_devices({"camera": CAMERA_TEMPLATES["genicam"]}, where="rig.json")
    with pytest.raises(ConfigError, match=f"^rig.json: {says}"):
        validate_devices({"camera": {**CAMERA_TEMPLATES["genicam"], field: value}}, where="rig.json")


def test_rig_init_then_check_on_the_shipped_producer(tmp_path, cli):
    """Frames grabbed in order, the missing exposure node named as a limit of the device; exit 0, no traceback."""
    from support.cli_runs import cli_process

    rig_file = _rig_file(tmp_path, _producer(), cli)
    before = open(rig_file).read()
    run = cli_process("check", "--rig", rig_file, "--out", str(tmp_path / "out"), timeout=120)
    assert run.code == 0, run.err
    text = run.out + run.err
    assert "Traceback" not in text
    assert "limit of the device: no ExposureTime node: capture.camera.exposure_us 33333 is not applied" in text
    assert "camera: 30 frames of 400x400 uint8" in text and "0 dropped, 0 repeated (frame ids)" in text
    check = json.loads((tmp_path / "out" / "check.json").read_text())
    assert check["camera_only"] and check["frames"] == 30 and check["dropped_frames"] == 0
    assert check["frame_period_s"] == pytest.approx(1 / 30, rel=0.5)
    assert any(line.startswith("no ExposureTime node") for line in check["camera_limits"])
    assert (tmp_path / "out" / "check.png").stat().st_size > 0
    assert open(rig_file).read() == before          # no latency measured: the rig file is left as it was


def test_the_live_page_streams_it(tmp_path, cli):
    from rangekit.ui.live import live_frame
    from rangekit.ui.rig_holder import RigHolder

    holder = RigHolder.hardware(_rig_file(tmp_path, _producer(), cli))
    try:
        assert holder.fault is None and holder.status()["camera"]["connected"]
        frames = [holder.grab() for _ in range(3)]
        assert all(f.shape == (400, 400) for f in frames)
        shown = live_frame(frames[-1], holder.full_scale, seq=3)
        assert shown.jpeg[:2] == b"\xff\xd8" and (shown.width, shown.height) == (400, 400)
    finally:
        holder.close()


def test_pixel_formats_become_frames():
    from rangekit.drivers.genicam.frames import to_frame
    from rangekit.errors import DeviceError

    mosaic = np.zeros((4, 6), np.uint16)
    mosaic[0::2, 0::2] = 3000                       # BayerRG12: red at (0, 0), so only red is lit
    grey = to_frame(mosaic.ravel(), 6, 4, "BayerRG12")
    assert grey.dtype == np.uint16 and grey.shape == (4, 6)
    assert grey[1:3, 1:4].mean() == pytest.approx(1000, abs=1)      # red 3000, green and blue 0: grey = mean
    mono = to_frame(np.arange(12, dtype=np.uint16) * 300, 4, 3, "Mono12")
    assert mono.shape == (3, 4) and mono.max() == 3300
    rgba = np.arange(2 * 3 * 4, dtype=np.uint8)
    rgb = to_frame(rgba, 3, 2, "RGBa8")
    assert rgb.shape == (2, 3, 3) and rgb[0, 0].tolist() == [0, 1, 2]
    assert to_frame(rgba[:18], 3, 2, "BGR8")[0, 0].tolist() == [2, 1, 0]
    with pytest.raises(DeviceError, match="a Mono8 frame of 4x4 needs 16 values, the buffer has 12"):
        to_frame(np.zeros(12, np.uint8), 4, 4, "Mono8")


def test_devices_lists_the_producers_cameras(cli, monkeypatch, tmp_path):
    from rangekit.drivers.genicam.producer import GENTL_ENV

    monkeypatch.setenv(GENTL_ENV, _producer())
    run = cli("devices", "--timeout", "0")
    assert run.code == 0, run.err
    assert "genicam cameras: (search limit" in run.out
    assert "  1  Machine Vision Games Ltd. Viky  id VikyTL_DEV_green" in run.out
    monkeypatch.setenv(GENTL_ENV, str(tmp_path / "nothing.cti"))
    run = cli("devices", "--timeout", "0")
    assert run.code == 0 and "genicam cameras: not listed: GENICAM_GENTL64_PATH entry" in run.out
    assert "nothing.cti' does not exist" in run.out


def test_a_12_bit_pixel_format_needs_capture_bits(tmp_path, cli):
    from rangekit.drivers import open_rig_devices
    from rangekit.rig.rig_file import load_rig

    path = _rig_file(tmp_path, _producer(), cli)
    rig = json.loads(open(path).read())
    rig["devices"]["camera"]["pixel_format"] = "Mono12"
    open(path, "w").write(json.dumps(rig))
    with pytest.raises(ConfigError, match="capture.bits: devices.camera.pixel_format Mono12 gives 12-bit values"):
        open_rig_devices(load_rig(path), where=path)


def test_importing_the_driver_imports_neither_harvesters_nor_genicam():
    import subprocess
    import sys

    code = ("import sys, rangekit.drivers.genicam.camera, rangekit.cli\n"
            "print(sorted(m for m in ('harvesters', 'genicam', 'cv2') if m in sys.modules))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0, res.stderr
    assert "harvesters" not in res.stdout and "genicam" not in res.stdout, res.stdout
