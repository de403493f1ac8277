"""The Check page's job (issue 37): ``rangekit check`` on the app's simulated rig, its suggested rig-file changes
applied with one click, measured again."""

from __future__ import annotations

import json
import time

import pytest

from support.ui_server import start_ui


def _finished(server, timeout: float = 180.0) -> dict:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        state = json.loads(server.request("/api/check")[1])
        if state["state"] in ("done", "failed"):
            return state
        # A page polls the device status meanwhile: it must not talk to the turntable's serial link while the
        # check does (interleaved queries once broke the check's status reads).
        for _ in range(5):
            assert json.loads(server.request("/api/status")[1])["rig"]["busy"] in ("check", None)
        time.sleep(0.05)
    raise AssertionError("the check did not finish")


@pytest.fixture(scope="module")
def shiny(tmp_path_factory):
    s = start_ui(tmp_path_factory.mktemp("sessions"), "--object", "shiny")
    yield s
    s.stop()


def test_the_suggested_exposure_applied_stops_the_saturation(shiny):
    status, body, _ = shiny.request("/api/check/apply", data={})
    assert status == 400 and json.loads(body)["error"] == "no finished check to apply: run the check first"
    assert shiny.request("/api/check/run", data={})[0] == 200
    status, body, _ = shiny.request("/api/check/run", data={})          # one at a time
    assert status == 400 and json.loads(body)["error"] == "a check is running already"
    first = _finished(shiny)
    assert first["state"] == "done", first
    res = first["result"]
    assert res["saturated_fraction"] > 0.001 and res["suggested_exposure_us"] < res["exposure_us"]
    assert any("saturates" in line for line in first["advice"]) and first["progress"]
    status, png, headers = shiny.request("/api/check/figure.png")
    assert status == 200 and png[:8] == b"\x89PNG\r\n\x1a\n" and headers["content-type"] == "image/png"

    status, body, _ = shiny.request("/api/check/apply", data={})
    assert status == 200
    rig_file = json.loads(body)["rig"]["rig_file"]
    written = json.loads(open(rig_file).read())["capture"]
    assert written["camera"]["exposure_us"] == first["suggested"]["capture.camera.exposure_us"]
    assert written["pattern_delay_s"] == first["suggested"]["capture.pattern_delay_s"]

    shiny.request("/api/check/run", data={})
    second = _finished(shiny)["result"]
    assert second["exposure_us"] == pytest.approx(first["suggested"]["capture.camera.exposure_us"])
    # The suggestion puts the object's 99th percentile at 90% of full scale: under 1% of it saturates now (the
    # shiny object's specular highlights), a fraction of before.
    print(f"\nsaturated {res['saturated_fraction']:.2%} at {res['exposure_us']:.0f} us, "
          f"{second['saturated_fraction']:.2%} at {second['exposure_us']:.0f} us; p99 {second['white_p99']:.3f}")
    assert second["saturated_fraction"] < min(0.01, res["saturated_fraction"] / 3)
    assert 0.8 <= second["white_p99"] <= 0.97
