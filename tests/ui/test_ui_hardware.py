"""``rangekit ui --rig RIG.json``: a hardware rig file (issue 37). Its checks fail before the server starts, with
the command line's one line; a device that does not open is shown on the page with the driver's one line (the
same ``rangekit check --rig`` prints), the server lives on, and reconnect tries again. The turntable here is the
simulated Horus board over a pty; the projector's control port is absent, as an unplugged one is."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import pytest

from support.ui_server import start_ui


@pytest.fixture
def rig_file(tmp_path):
    from rangekit.sim.devices.firmware import start_firmware

    template = subprocess.run([sys.executable, "-m", "rangekit", "rig", "init"], capture_output=True, text=True,
                              check=True).stdout
    with start_firmware("horus", time_scale=0.01) as board:
        data = json.loads(template)
        data["devices"]["turntable"]["port"] = board.port
        data["devices"]["projector"]["control"]["port"] = str(tmp_path / "no-such-port")
        data["devices"]["camera"]["search_timeout_s"] = 0.2
        path = tmp_path / "rig.json"
        path.write_text(json.dumps(data))
        yield path


def _cli_error(*args) -> str:
    run = subprocess.run([sys.executable, "-m", "rangekit", *args], capture_output=True, text=True,
                         stdin=subprocess.DEVNULL, timeout=120)
    lines = run.stderr.strip().splitlines()
    assert run.returncode != 0 and len(lines) == 1 and lines[0].startswith("rangekit: error: "), run.stderr
    return lines[0].removeprefix("rangekit: error: ")


def test_a_device_that_does_not_open_is_the_drivers_one_line_on_the_page(tmp_path, rig_file):
    words = _cli_error("check", "--rig", str(rig_file))
    assert "no-such-port" in words
    server = start_ui(tmp_path, "--rig", str(rig_file))
    try:
        rig = json.loads(server.request("/api/status")[1])["rig"]
        assert rig["source"] == "hardware" and rig["fault"] == words and not rig["camera"]["connected"]
        for path, data in (("/api/turntable", {"degrees": 10}), ("/api/pattern", {"name": "white"}),
                           ("/api/calibrate/start", {"poses": 5})):
            status, body, _ = server.request(path, data=data)
            assert status == 400 and json.loads(body) == {"error": f"not connected: {words}"}, (path, body)
        status, body, _ = server.request("/api/reconnect", data={})            # tried again, the same answer
        assert status == 200 and json.loads(body)["rig"]["fault"] == words
        assert server.request("/api/check/run", data={})[0] == 200
        deadline = time.monotonic() + 60
        while (check := json.loads(server.request("/api/check")[1]))["state"] == "running" and time.monotonic() < deadline:
            time.sleep(0.2)
        assert check == {"state": "failed", "error": f"not connected: {words}", "progress": []}
    finally:
        err = server.stop()
    assert f"rangekit ui: warning: {words}" in err and "Traceback" not in err


def test_a_rig_file_that_fails_its_checks_stops_the_app_with_the_clis_line(tmp_path, rig_file):
    data = json.loads(rig_file.read_text())
    data["devices"]["turntable"]["protocol"] = "grbl9"
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(data))
    words = _cli_error("check", "--rig", str(bad))
    assert "devices.turntable.protocol" in words
    run = subprocess.run([sys.executable, "-m", "rangekit", "ui", "--rig", str(bad), "--port", "0", "--sessions",
                          str(tmp_path)], capture_output=True, text=True, stdin=subprocess.DEVNULL, timeout=120)
    assert run.returncode != 0 and run.stderr.strip() == f"rangekit: error: {words}" and run.stdout == ""
