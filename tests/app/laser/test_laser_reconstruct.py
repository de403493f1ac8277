"""``rangekit reconstruct`` of a simulated laser capture: each laser's line peaks triangulated
against its plane, measured against the simulator's lit curve; a laser that lights nothing is an error
naming its frame, never an empty cloud."""

from __future__ import annotations

import shutil

import numpy as np
import pytest
from scipy.spatial import cKDTree

from rangekit.cli import main


@pytest.fixture(scope="module")
def laser_capture(tmp_path_factory):
    out = tmp_path_factory.mktemp("laser") / "cap"
    assert main(["sim", "render", "--sensor", "laser", "--angle-deg", "30", "--out", str(out)]) == 0
    return out


def test_reconstruct_triangulates_each_laser_on_its_plane(laser_capture, tmp_path, capsys):
    from rangekit.formats.clouds import load_cloud
    from rangekit.rig.rig_file import load_rig

    assert main(["reconstruct", str(laser_capture), "--out", str(tmp_path / "c.ply")]) == 0
    assert "laser 0:" in capsys.readouterr().out
    P = load_cloud(tmp_path / "c.ply").points
    truth = np.load(laser_capture / "ground_truth.npz")
    curves = [truth[f"laser{k}_curve_xyz"] for k in range(2)]
    assert len(P) > 0.8 * sum(len(np.unique(np.rint(truth[f"laser{k}_curve_uv"][:, 1]))) for k in range(2))
    # Every point lies on one of the two laser planes and near that laser's true lit curve. The distance to
    # the nearest curve sample is an upper bound of the error (samples are ~0.17 mm apart).
    planes = np.stack([laser.plane for laser in load_rig(laser_capture / "rig.json").lasers])
    on_plane = np.min(np.abs(np.c_[P, np.ones(len(P))] @ planes.T), axis=1)
    assert on_plane.max() < 1e-9
    d = cKDTree(np.concatenate(curves)).query(P)[0]
    assert np.sqrt(np.mean(d ** 2)) < 0.08e-3 and np.percentile(d, 99) < 0.2e-3


def test_a_laser_that_lights_nothing_is_named(laser_capture, tmp_path, capsys):
    bad = tmp_path / "cap"
    shutil.copytree(laser_capture, bad)
    shutil.copy(bad / "off.png", bad / "laser1.png")   # laser 1 did not switch on
    assert main(["reconstruct", str(bad), "--out", str(tmp_path / "c.ply")]) == 1
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("rangekit: error: ") and "laser1.png" in err and "no laser line visible" in err
    assert not (tmp_path / "c.ply").exists()
    (bad / "laser1.png").unlink()
    assert main(["reconstruct", str(bad), "--out", str(tmp_path / "c.ply")]) == 1
    assert "missing laser1.png" in capsys.readouterr().err


def test_the_full_scale_comes_from_the_capture_or_the_rig(laser_capture):
    from rangekit.formats.capture import capture_full_scale
    from rangekit.formats.laser_capture import load_laser_capture
    from rangekit.rig.rig_file import load_rig

    assert load_laser_capture(laser_capture).full_scale == 255.0   # capture.json: imaging bits 8
    rig = load_rig(laser_capture / "rig.json")
    assert capture_full_scale({"imaging": {"bits": 12}}, rig) == 4095.0   # a 12-bit camera in 16-bit PNGs
    assert capture_full_scale({}, rig) == float(2 ** rig.capture["bits"] - 1)
    assert capture_full_scale({"imaging": "junk"}, None) is None
