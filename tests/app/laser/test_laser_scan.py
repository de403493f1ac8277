"""``rangekit scan --method laser``: a turntable laser-line session, acquired crash-safe and
resumable like coded light, processed into a cloud and a mesh measured against the simulator's truth.

The full 400-step scans of lumpy and of the upright bunny run in ``make test-slow``, and so does a 12-step
scan (30 degrees per step, 18 s: ``make test`` keeps to its 8 minutes) that checks the chain end to end and the session's contents."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rangekit.cli import main
from rangekit.formats.sessions.session import Session


@pytest.fixture(scope="module")
def laser_scan(tmp_path_factory):
    out = tmp_path_factory.mktemp("laserscan") / "scan"
    assert main(["scan", "--method", "laser", "--steps", "12", "--out", str(out), "--no-report"]) == 0
    return out


@pytest.mark.slow
def test_laser_scan_cloud_matches_the_true_surface(laser_scan):
    summary = json.loads((laser_scan / "summary.json").read_text())
    acc = summary["accuracy"]
    # The merged cloud: every point's distance to the true surface.
    assert acc["cloud_rms"] < 0.1e-3 and acc["cloud_p95"] < 0.15e-3, acc
    assert acc["n_cloud"] > 12 * 2 * 300
    assert summary["mesh_watertight"]["watertight"] and summary["mesh"]["file"] == "mesh.ply"
    assert (laser_scan / "mesh_watertight.ply").is_file()
    lasers = summary["laser"]["lasers"]
    assert [d["name"] for d in lasers] == ["laser0", "laser1"]
    assert all(d["points"] > 12 * 300 and d["steps_without_line"] == 0 for d in lasers)
    assert summary["registration_rmse_m"] is None and summary["edges"] == []
    assert len(summary["views"]) == 12


@pytest.mark.slow
def test_laser_session_holds_capture_folders(laser_scan, tmp_path, capsys):
    session = Session.load(laser_scan)
    assert session.is_laser and session.pattern.frame_files == ["off.png", "laser0.png", "laser1.png"]
    assert json.loads((laser_scan / "session.json").read_text())["pattern"] == {
        "method": "laser", "lasers": 2, "frames": ["off", "laser0", "laser1"]}
    v = session.views[7]
    assert sorted(v.sha256) == ["laser0.png", "laser1.png", "off.png"]
    # Each step folder is a laser capture: 'rangekit reconstruct' triangulates it in the world at its angle,
    # and the step's pose in poses.json turns those points onto the merged cloud.
    from rangekit.formats.clouds import load_cloud
    from rangekit.formats.poses import load_poses
    from scipy.spatial import cKDTree

    assert main(["reconstruct", str(v.folder), "--out", str(tmp_path / "v7.ply")]) == 0
    P = load_cloud(tmp_path / "v7.ply").points
    T = load_poses(laser_scan / "poses.json")[1][7]
    merged = load_cloud(laser_scan / "merged.ply").points
    P = P @ T[:3, :3].T + T[:3, 3]
    d = cKDTree(merged).query(P)[0]
    assert np.median(d) < 1e-6   # the same points (the table band aside)


def test_interrupted_laser_acquisition_resumes_to_the_same_frames(tmp_path):
    """A camera unplugged mid-step: the finished steps stay, no laser is left on, and the resumed session
    holds the same bytes as an uninterrupted one."""
    from rangekit.app.acquire.acquire import acquire
    from rangekit.errors import DeviceError
    from rangekit.formats.sessions.session import ScanPlan
    from rangekit.laser.sequence import LaserSequence
    from rangekit.sim import SimRig, default_scene
    from rangekit.sim.laser.rig import laser_rig

    def devices():
        return SimRig(default_scene("sphere"), laser_rig(), light="laser", seed=3)

    plan, spec = ScanPlan(n_views=5), LaserSequence(2)
    ref = acquire(devices(), laser_rig(), spec, tmp_path / "ref", plan=plan)
    broken = devices()
    broken.inject_fault("camera", after=8)   # the 9th frame: step 2, laser1
    with pytest.raises(DeviceError, match=r"view 2 .*frame 2 \(laser1\): camera.*rangekit scan --resume"):
        acquire(broken, laser_rig(), spec, tmp_path / "s", plan=plan)
    assert broken.turntable.lasers_on == set()
    assert [v.done for v in Session.load(tmp_path / "s").views] == [True, True, False, False, False]
    assert not list((tmp_path / "s").glob("*.partial"))
    done = acquire(devices(), laser_rig(), spec, tmp_path / "s", plan=plan, resume=True)
    assert all(v.done for v in done.views)
    for v_ref, v in zip(ref.views, done.views):
        assert v.sha256 == v_ref.sha256
        for name in spec.frame_files:
            assert (v.folder / name).read_bytes() == (v_ref.folder / name).read_bytes()


def test_laser_scan_options(tmp_path, capsys):
    assert main(["scan", "--method", "laser", "--patterns", "graycode", "--out", str(tmp_path / "a")]) == 2
    assert "--patterns" in capsys.readouterr().err
    assert main(["scan", "--steps", "40", "--out", str(tmp_path / "b")]) == 2
    assert "--steps" in capsys.readouterr().err
    assert main(["scan", "--method", "laser", "--steps", "40", "--views", "12", "--out", str(tmp_path / "c")]) == 2
    assert main(["scan", "--method", "laser", "--up", "0", "1", "0", "--out", str(tmp_path / "d")]) == 2
    assert "--up" in capsys.readouterr().err
    assert not any((tmp_path / n).exists() for n in "abcd")


@pytest.mark.slow
def test_laser_session_refuses_tsdf(laser_scan, capsys):
    assert main(["process", str(laser_scan), "--fusion", "tsdf", "--no-report"]) == 1
    assert "fuses with poisson" in capsys.readouterr().err




@pytest.mark.slow
@pytest.mark.parametrize("obj", ["lumpy", "bunny"])
def test_full_laser_scan_with_calibrated_planes(obj, tmp_path):
    """The acceptance scan: 400 steps, two lasers, planes calibrated from 10 simulated board poses; the merged
    cloud within 0.1 mm RMS of the true surface, for lumpy and for the Stanford bunny standing upright."""
    from support.shared_data import require_shared

    bunny = require_shared("stanford-bunny", "bun_zipper.ply") if obj == "bunny" else None
    args = ["--object", str(bunny), "--up", "0", "1", "0"] if obj == "bunny" else []
    out = tmp_path / "scan"
    assert main(["scan", "--method", "laser", "--out", str(out), "--no-report", *args]) == 0
    summary = json.loads((out / "summary.json").read_text())
    acc = summary["accuracy"]
    assert acc["cloud_rms"] <= 0.1e-3 and summary["mesh_watertight"]["watertight"], acc
    assert len(summary["views"]) == 400 and acc["n_cloud"] > 250_000
    # The lasers were calibrated, not copied from the simulator's truth.
    from rangekit.rig.rig_file import load_rig
    from rangekit.sim.laser.rig import laser_rig

    planes = [laser.plane for laser in load_rig(out / "rig.json").lasers]
    true = [laser.plane for laser in laser_rig().lasers]
    assert all(0 < np.abs(p - q).max() < 1e-4 for p, q in zip(planes, true))
