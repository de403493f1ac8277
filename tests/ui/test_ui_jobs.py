"""The Calibrate, Registration and Sessions jobs of the web app through its HTTP API (issue 37): the wizard's
steps and refusals, a calibration from recorded folders, clouds registered against their true motion, meshes
exported. The whole path in a browser is tests/ui/test_ui_browser.py."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import time

import numpy as np
import pytest

from support.ui_server import serving, start_ui


def _post(server, path, data=None):
    status, body, _ = server.request(path, data=data if data is not None else {})
    return status, json.loads(body)


def _get(server, path):
    return json.loads(server.request(path)[1])


def _wait(server, path, done, timeout=300.0):
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        state = _get(server, path)
        if done(state):
            return state
        time.sleep(0.2)
    raise AssertionError(f"{path}: never finished: {state}")


server = pytest.fixture(scope="module", name="server")(serving)


def test_the_wizard_refuses_steps_out_of_turn_and_cancels_cleanly(server):
    assert _post(server, "/api/calibrate/capture") == (400, {"error": "capture: the calibration is idle, not placing"})
    assert _post(server, "/api/calibrate/keep")[1]["error"] == "keep or retake: the calibration is idle, not review"
    assert _post(server, "/api/calibrate/cancel")[1]["error"] == "no calibration is running"
    status, reply = _post(server, "/api/calibrate/start", {"poses": "abc"})
    assert status == 400 and reply["error"] == "poses: expected a whole number 3-60, found 'abc'"
    assert _post(server, "/api/calibrate/start", {"poses": 2})[1]["error"].startswith("poses: expected")
    assert _post(server, "/api/calibrate/jump")[0] == 404
    status, reply = _post(server, "/api/calibrate/start", {"poses": 5})
    assert status == 200, reply
    placing = _wait(server, "/api/calibrate", lambda s: s["state"] == "placing", timeout=120)
    assert placing["pose"] == 0 and placing["simulated"]
    assert _get(server, "/api/status")["rig"]["busy"] == "calibration"
    assert _post(server, "/api/calibrate/start", {"poses": 5})[1]["error"] == "a calibration is running already"
    assert _post(server, "/api/pattern", {"name": "black"})[1]["error"].startswith("the rig is busy: calibration")
    status, reply = _post(server, "/api/calibrate/drag", {"dx": "left", "dy": 0})
    assert status == 400 and reply["error"] == "dx: expected a number of pixels (-5000 to 5000), found 'left'"
    assert _post(server, "/api/calibrate/drag", {"dx": 40, "dy": -10})[0] == 200
    assert _post(server, "/api/calibrate/next")[0] == 200
    assert _post(server, "/api/calibrate/cancel")[0] == 200
    state = _wait(server, "/api/calibrate", lambda s: s["state"] == "cancelled")
    assert state["poses"] == []
    rig = _wait(server, "/api/status", lambda s: s["rig"]["busy"] is None)["rig"]
    assert rig["pattern"] == "white"          # the Live page's pattern shown again
    assert not (server.sessions / "coverage.png").exists()


def test_one_pose_kept_shows_its_error_coverage_and_a_hint_then_retake_removes_it(server):
    assert _post(server, "/api/calibrate/start", {"poses": 4, "seed": 1})[0] == 200
    _wait(server, "/api/calibrate", lambda s: s["state"] == "placing", timeout=120)
    assert _post(server, "/api/calibrate/capture")[0] == 200
    review = _wait(server, "/api/calibrate", lambda s: s["state"] == "review", timeout=120)
    (pose,) = review["poses"]
    assert pose["kept"] and pose["corners"] == 54 and 0 < pose["reprojection_px"] < 0.1, pose
    assert review["hint"].startswith("next: the board near the") and review["pictures"] == ["coverage", "tilts"]
    for name in ("coverage", "tilts"):
        status, png, headers = server.request(f"/api/calibrate/picture/{name}.png")
        assert status == 200 and png[:8] == b"\x89PNG\r\n\x1a\n" and headers["content-type"] == "image/png"
    assert _post(server, "/api/calibrate/retake")[0] == 200
    again = _wait(server, "/api/calibrate", lambda s: s["state"] == "placing", timeout=60)
    assert again["pose"] == 0 and again["poses"] == []
    assert _post(server, "/api/calibrate/cancel")[0] == 200
    _wait(server, "/api/status", lambda s: s["rig"]["busy"] is None)


def test_recorded_folders_are_confined_and_checked_field_by_field(server):
    (server.sessions / "calib" / "seq1").mkdir(parents=True)
    base = {"captures": "calib/seq*", "pattern": "slstudio:calibration", "projector": "64x40", "out": "r.json"}
    for change, error in (({"captures": "../x"}, "path '../x': refused ('..' leads out of the sessions folder)"),
                          ({"captures": "/etc"}, "path '/etc': refused (absolute; name it relative to the sessions folder)"),
                          ({"captures": "calib/none*"}, "captures: calib/none*: no folder matches under the sessions folder"),
                          ({"captures": ""}, "captures: name the pose folders under the sessions folder, e.g. calib/pose_*"),
                          ({"projector": "big"}, "projector: expected WIDTHxHEIGHT in pixels, e.g. 1824x1140, found 'big'"),
                          ({"pattern": "nope"}, "pattern: 'nope': unknown capture layout; known: "),
                          ({"out": "r.txt"}, "out: expected a rig file name ending in .json, found 'r.txt'"),
                          ({"cols": 2.5}, "cols: expected a whole number of squares 3-60, found 2.5")):
        status, reply = _post(server, "/api/calibrate-recorded/start", {**base, **change})
        assert status == 400 and reply["error"].startswith(error), (change, reply)
    # One empty folder: the calibration's own one-line refusal, shown as the job's state; nothing written.
    assert _post(server, "/api/calibrate-recorded/start", base)[0] == 200
    state = _wait(server, "/api/calibrate-recorded", lambda s: s["state"] != "running")
    assert state["state"] == "failed" and "\n" not in state["error"] and "at least 3" in state["error"], state
    assert not (server.sessions / "r.json").exists()
    # A file already there is the user's: refused by its field unless the page says to replace it.
    (server.sessions / "mine.json").write_text("{}")
    status, reply = _post(server, "/api/calibrate-recorded/start", {**base, "out": "mine.json"})
    assert status == 400 and reply["error"].startswith("out: mine.json exists under the sessions folder"), reply
    assert (server.sessions / "mine.json").read_text() == "{}"
    assert _post(server, "/api/calibrate-recorded/start", {**base, "out": "mine.json", "replace": True})[0] == 200
    assert _wait(server, "/api/calibrate-recorded", lambda s: s["state"] != "running")["state"] == "failed"
    assert (server.sessions / "mine.json").read_text() == "{}"     # a failed run replaces nothing


def _surface(n: int, rng) -> np.ndarray:
    """Points (n, 3) metres of a bumpy, asymmetric patch 8 x 6 cm."""
    xy = rng.uniform([-0.04, -0.03], [0.04, 0.03], (n, 2))
    z = 0.004 * np.sin(70 * xy[:, 0]) * np.cos(50 * xy[:, 1]) + 0.006 * xy[:, 0] / 0.04 + 0.5
    return np.column_stack([xy, z])


def test_two_clouds_register_to_their_true_motion_and_save_under_a_name(server):
    from rangekit.formats.clouds import save_cloud
    from rangekit.geometry import apply_T, invert_T, make_T
    from rangekit.surface.cloud import PointCloud

    rng = np.random.default_rng(4)
    folder = server.sessions / "pair"
    folder.mkdir()
    a, b = _surface(20000, rng), _surface(20000, rng)
    angle = np.radians(3.0)
    R = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    T_a_b = make_T(R, np.array([0.002, -0.001, 0.0005]))
    save_cloud(folder / "a.ply", PointCloud(a))
    save_cloud(folder / "b.ply", PointCloud(apply_T(invert_T(T_a_b), b)))    # b seen from its own frame
    assert "pair/a.ply" in _get(server, "/api/register/clouds")["clouds"]
    assert _post(server, "/api/register/start", {"files": ["pair/a.ply"]})[1]["error"].startswith(
        "clouds: pick at least 2 clouds")
    assert _post(server, "/api/register/start", {"files": ["pair/a.ply", "../b.ply"]})[1]["error"].startswith(
        "path '../b.ply': refused")
    assert _post(server, "/api/register/save", {"name": "x"})[1]["error"].startswith("nothing to save")
    assert _post(server, "/api/register/start", {"files": ["pair/a.ply", "pair/b.ply"], "neighbours": 0})[0] == 200
    state = _wait(server, "/api/register", lambda s: s["state"] != "running")
    assert state["state"] == "done", state
    (pair,) = state["pairs"]
    assert pair["accepted"] and pair["rmse_mm"] < 0.05 and pair["overlap_percent"] > 90, pair
    points_mm = np.frombuffer(server.request("/api/register/points/1")[1], np.float32).reshape(-1, 3)
    assert len(points_mm) == 20000
    # b's points placed by the registered pose land on a's surface: the true motion recovered.
    placed = points_mm.astype(np.float64) / 1e3
    assert np.sqrt(np.mean(np.sum((placed - b) ** 2, axis=1))) < 2e-5
    assert _post(server, "/api/register/save", {"name": "../out"})[1]["error"].startswith("name: '../out': begins with '.'")
    assert _post(server, "/api/register/save", {"name": ".registering"})[1]["error"].startswith("name: '.registering'")
    assert _post(server, "/api/register/save", {"name": "pair"})[1]["error"] == (
        "name: pair: exists under the sessions folder; choose another name")
    assert _post(server, "/api/register/save", {"name": "pair-registered"})[1]["saved"] == "pair-registered"
    saved = json.loads((server.sessions / "pair-registered" / "poses.json").read_text())
    assert saved and (server.sessions / "pair-registered" / "merged.ply").is_file()


@pytest.fixture(scope="module")
def processed(reference_session, tmp_path_factory):
    sessions = tmp_path_factory.mktemp("processed")
    shutil.copytree(reference_session, sessions / "done")
    subprocess.run([sys.executable, "-m", "rangekit", "-q", "process", str(sessions / "done"), "--no-report"],
                   check=True, stdin=subprocess.DEVNULL, capture_output=True, timeout=600)
    s = start_ui(sessions)
    s.sessions = sessions
    yield s
    s.stop()


def test_export_writes_each_format_of_scan_format_from_the_same_mesh(processed):
    from rangekit.formats.meshes import load_mesh

    folder = processed.sessions / "done"
    assert _post(processed, "/api/sessions/done/export", {"format": "dxf"})[1]["error"] == (
        "format 'dxf': expected one of ply, obj, stl, glb")
    assert _post(processed, "/api/sessions/nothere/export", {"format": "obj"})[1]["error"] == (
        "nothere/mesh.ply: not there; process the session first")
    for fmt in ("obj", "stl", "glb"):
        status, reply = _post(processed, "/api/sessions/done/export", {"format": fmt})
        assert status == 200 and reply["files"] == [f"mesh.{fmt}", f"mesh_watertight.{fmt}"], reply
        for stem in ("mesh", "mesh_watertight"):
            ply, out = load_mesh(folder / f"{stem}.ply"), load_mesh(folder / f"{stem}.{fmt}")
            assert len(out.triangles) == len(ply.triangles)
            # The same corners, triangle by triangle (STL repeats a vertex per triangle; float32 files round to
            # 1e-7 m). Not compared as sets rounded to 1 um: Poisson leaves distinct vertices 0.04 um apart, which
            # float32 can put on either side of a rounding step.
            corners = [np.asarray(m.vertices)[np.asarray(m.triangles)] for m in (ply, out)]
            assert np.abs(corners[0] - corners[1]).max() <= 1.5e-6
            assert processed.request(f"/api/sessions/done/files/{stem}.{fmt}")[0] == 200
    assert _post(processed, "/api/sessions/done/process", {"fusion": "marching"})[1]["error"] == (
        "fusion: expected poisson or tsdf or blocks, found 'marching'")
    status, body, _ = processed.request("/api/sessions/%2E%2E/process", data={})
    assert status == 400 and json.loads(body)["error"].startswith("path '..': refused")


@pytest.mark.slow
def test_slstudios_recorded_poses_calibrate_as_the_command_line_does(tmp_path):
    """SLStudio's five recorded poses (../shared/data/slstudio-skull/calibration, copied into a sessions folder)
    calibrated from the page's form: the same rig file as ``rangekit calibrate --captures`` (to 1e-6)."""
    from support.shared_data import require_shared

    skull = require_shared("slstudio-skull")
    sessions = tmp_path / "sessions"
    for seq in ("calseq1", "calseq3", "calseq4", "calseq5", "calseq6"):
        shutil.copytree(skull / "calibration" / seq, sessions / "calib" / seq)
    server = start_ui(sessions)
    try:
        status, reply = _post(server, "/api/calibrate-recorded/start", {
            "captures": "calib/calseq*", "pattern": "slstudio:calibration", "projector": "1824x1140",
            "out": "slstudio-rig.json", "cols": 14, "rows": 10, "square_mm": 10})
        assert status == 200, reply
        state = _wait(server, "/api/calibrate-recorded", lambda s: s["state"] != "running", timeout=900)
    finally:
        server.stop()
    assert state["state"] == "done", state
    assert any("pose" in line for line in state["lines"])
    cli = subprocess.run([sys.executable, "-m", "rangekit", "-q", "calibrate", "--captures",
                          *sorted(str(p) for p in (sessions / "calib").iterdir()), "--pattern", "slstudio:calibration",
                          "--projector", "1824x1140", "--cols", "14", "--rows", "10", "--square-mm", "10",
                          "--out", str(tmp_path / "cli-rig.json")], capture_output=True, text=True, timeout=900)
    assert cli.returncode == 0, cli.stderr
    # The same rig: two runs of the command line itself differ by up to 5e-6 in a distortion coefficient and in
    # the 8th digit of the focal lengths (OpenCV's threaded solvers), so every number of the file is compared to
    # 1e-6 relative or 2e-5 absolute, every other field exactly.
    def numbers(value):
        if isinstance(value, dict):
            return {k: numbers(v) for k, v in value.items()}
        if isinstance(value, list):
            return [numbers(v) for v in value]
        return pytest.approx(value, rel=1e-6, abs=2e-5) if isinstance(value, float) else value
    page_rig = json.loads((sessions / "slstudio-rig.json").read_text())
    assert page_rig == numbers(json.loads((tmp_path / "cli-rig.json").read_text()))
