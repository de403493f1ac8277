"""Options never silently ignored, and error texts a person can act on (issue 48): an option that needs another
is refused naming both; a simulator option is an option error (exit 2) in the unit the user gave; an implausible
board square is refused before any pose; duplicate pose folders are named; no value an error quotes is longer
than a line; a huge Stanford .conf is refused at once."""

from __future__ import annotations

import time

import cv2
import numpy as np
import pytest

from support.cli_runs import assert_error
from rangekit.errors import ConfigError, MESSAGE_LIMIT, bounded_message, shown


@pytest.mark.parametrize("option", [["--readout-frames", "0.5"], ["--motion", "vibration"]])
def test_a_motion_option_without_motion_mm_is_refused(cli, tmp_path, option):
    run = cli("sim", "render", *option, "--out", tmp_path / "cap")
    assert_error(run, 2, option[0], "only with --motion-mm", "no --motion-mm")
    assert not (tmp_path / "cap").exists()


def test_simulator_options_are_option_errors_in_the_users_unit(cli, tmp_path):
    run = cli("sim", "render", "--motion-mm", "100", "--out", tmp_path / "a")
    line = assert_error(run, 2, "--motion-mm 100", "at most 50 mm")
    assert "metres" not in line and "amplitude" not in line
    run = cli("sim", "render", "--motion-mm", "1", "--motion", "wobble", "--out", tmp_path / "b")
    assert_error(run, 2, "--motion", "wobble")
    run = cli("sim", "render", "--motion-mm", "1", "--readout-frames", "2", "--out", tmp_path / "c")
    assert_error(run, 2, "--readout-frames", "0..1")
    run = cli("sim", "render", "--sensor", "tof", "--near", "20", "--far", "1", "--out", tmp_path / "d")
    line = assert_error(run, 2, "--near 20", "--far 1")
    assert "tof_scene" not in line
    assert not any((tmp_path / n).exists() for n in "abcd")


@pytest.mark.parametrize("square, unit", [("1e9", None), ("0.02", "--square-mm 20"), ("1000", None)])
def test_an_implausible_square_is_refused_before_any_pose(cli, tmp_path, square, unit):
    run = cli("calibrate", "--square-mm", square, "--out", tmp_path / "rig.json")
    line = assert_error(run, 2, f"--square-mm: {float(square):g} mm", "square side")
    if unit:
        assert unit in line
    assert "parallel" not in line and run.out == ""     # refused up front, nothing captured


def test_duplicate_pose_folders_are_named(cli, tmp_path):
    for name in "abc":
        (tmp_path / name).mkdir()
    a, b, c = (tmp_path / n for n in "abc")
    run = cli("calibrate", "--captures", a, b, c, a, tmp_path / "." / "a", "--pattern", "slstudio:calibration",
              "--projector", "64x32", "--out", tmp_path / "rig.json")
    assert_error(run, 2, "--captures", f"{a} given 3 times", "3 distinct folders of the 5 given")


def test_a_found_value_is_shown_short():
    big = np.arange(300 * 300, dtype=float).reshape(300, 300)
    text = shown(big)
    assert len(text) <= 90 and "shape (300, 300)" in text and text.startswith("[[0.0, 1.0")
    assert shown([1, 2, 3]) == "[1, 2, 3]"
    assert len(shown(list(range(100000)))) <= 90
    message = "x" * 800_000
    assert len(bounded_message(message)) <= MESSAGE_LIMIT + 100


def test_a_huge_matrix_in_a_calibration_file_gives_a_short_error(cli, tmp_path):
    from rangekit.formats.rig_files.importers import import_rig

    K = np.array([[1234.5, 0.0, 640.0], [0.0, 1233.9, 400.0], [0.0, 0.0, 1.0]])
    fs = cv2.FileStorage(str(tmp_path / "stereo.yaml"), cv2.FILE_STORAGE_WRITE)
    for k, v in dict(K1=K, D1=np.zeros((1, 5)), K2=K, D2=np.zeros((1, 5)), R=np.eye(3),
                     T=np.full((100_000, 1), 0.1), imageSize=np.array([[1280], [800]], float)).items():
        fs.write(k, v)
    fs.release()
    with pytest.raises(ConfigError, match="T: expected 3 finite numbers") as caught:
        import_rig(tmp_path / "stereo.yaml", projector_size=(1280, 800))
    assert len(str(caught.value)) < 400
    run = cli("rig", "import", tmp_path / "stereo.yaml", "--projector-size", "1280x800")
    line = assert_error(run, 1, "stereo.yaml", "T: expected 3 finite numbers", "shape (100000,)")
    assert len(line) < 400


def test_a_huge_stanford_conf_is_refused_at_once(tmp_path):
    from rangekit.formats.stanford_conf import MAX_CONF_SCANS, load_stanford_conf

    path = tmp_path / "big.conf"
    path.write_text("camera 0 0 0 0 0 0 1\n" + "bmesh s.ply 0.01 0.02 0.03 0 0 0 1\n" * 300_000)
    t0 = time.perf_counter()
    with pytest.raises(ConfigError, match=r"big.conf: line 4: more than 2 'bmesh' lines, but 2 scans were given"):
        load_stanford_conf(path, expected=2)
    with pytest.raises(ConfigError, match=rf"line {MAX_CONF_SCANS + 2}: more than {MAX_CONF_SCANS} 'bmesh' lines"):
        load_stanford_conf(path)
    assert time.perf_counter() - t0 < 3.0
    names, T = load_stanford_conf(_small_conf(tmp_path))
    assert names == ["a.ply", "b.ply"] and T.shape == (2, 4, 4)
    np.testing.assert_allclose(T[1][:3, :3], [[0, 1, 0], [-1, 0, 0], [0, 0, 1]], atol=1e-12)


def _small_conf(tmp_path):
    path = tmp_path / "small.conf"
    s = np.sqrt(0.5)
    path.write_text(f"bmesh a.ply 0 0 0 0 0 0 1\nbmesh b.ply 0.1 0 0 0 0 {s} {s}\n")
    return path


def test_any_plausible_square_can_be_simulated():
    """--square-mm 20.05 failed as "board_object('board'): Board.texture: square (0.02005 m) must be a whole number
    of texels ... texel=0.0001": the simulated board now takes the texel nearest 0.1 mm that divides the square."""
    from rangekit.boards import Board
    from rangekit.sim.scene.objects import board_object

    for square in (0.02005, 0.00055, 0.0073):
        obj = board_object(Board(cols=4, rows=3, square=square))
        assert obj.texture is not None


@pytest.mark.parametrize("field", ["schema", "projector_response", "capture"])
def test_a_huge_value_in_a_rig_file_gives_a_short_error(tmp_path, field):
    import json

    from rangekit.rig.rig_file import load_rig
    from rangekit.sim import default_rig

    data = default_rig().to_dict()
    data[field] = list(range(100_000))                     # 700 kB of numbers where an object or a name goes
    (tmp_path / "rig.json").write_text(json.dumps(data))
    with pytest.raises(ConfigError) as caught:
        load_rig(tmp_path / "rig.json")
    assert len(str(caught.value)) < 400, str(caught.value)[:1000]
    assert "100000 items" in str(caught.value)


@pytest.mark.parametrize("args, mentions", [
    (["--sensor", "tof-pulsed", "--steps", "4"], ["--steps", "only for --sensor tof"]),
    (["--sensor", "stereo", "--multipath", "0.2", "1"], ["--multipath", "only for --sensor tof"]),
    (["--size", "320x256"], ["--size", "only for --sensor tof, tof-pulsed, stereo or dots"]),
    (["--sensor", "dots", "--no-dots"], ["--no-dots", "only for --sensor stereo"]),
    (["--sensor", "tof", "--frequencies-mhz", "80", "80"], ["--frequencies-mhz 80 80", "frequencies, distinct, in MHz",
                                                              "80 more than once"]),
    # options with defaults once silently ignored by the other sensors
    (["--sensor", "dots", "--jitter-ps", "3"], ["--jitter-ps", "only for --sensor tof-pulsed"]),
    (["--sensor", "tof", "--jitter-ps", "3"], ["--jitter-ps", "only for --sensor tof-pulsed"]),
    (["--sensor", "stereo", "--plan", "luxonis"], ["--plan", "only for --sensor tof"]),
    (["--sensor", "tof-pulsed", "--plan", "luxonis"], ["--plan", "only for --sensor tof (continuous wave)"]),
    (["--near", "1"], ["--near", "only for --sensor tof or tof-pulsed"]),
    (["--sensor", "dots", "--far", "3"], ["--far", "only for --sensor tof or tof-pulsed"]),
    (["--sensor", "tof", "--global-fraction", "0.2"], ["--global-fraction", "only for --sensor projector"]),
    (["--sensor", "dots", "--bits", "12"], ["--bits", "only for --sensor projector"]),
    (["--sensor", "stereo", "--angle-deg", "30"], ["--angle-deg", "only for --sensor projector"]),
    (["--sensor", "dots", "--no-noise"], ["--no-noise", "not for --sensor dots"]),
    (["--sensor", "tof", "--plan", "kinect", "--frequencies-mhz", "20", "30"], ["--plan kinect with --frequencies-mhz"]),
    # out of what the simulator models
    (["--global-fraction", "50"], ["--global-fraction", "expected a number in 0..1", "'50'"]),
    (["--sensor", "tof", "--frequencies-mhz", "1e-9"], ["--frequencies-mhz", "expected a number in 1..1000", "'1e-9'"]),
])
def test_an_option_of_another_sensor_is_refused(cli, tmp_path, args, mentions):
    run = cli("sim", "render", *args, "--out", tmp_path / "cap")
    line = assert_error(run, 2, *mentions)
    assert "80000000" not in line and "FrequencyPlan" not in line
    assert not (tmp_path / "cap").exists()
