"""Calibration from recorded sequences (``rangekit calibrate --captures DIR ... --pattern PRESET --projector WxH``,
issue 35 item 4): what is refused and how, the simulator's board poses recorded in SLStudio's calibration
layout giving back its true rig, and SLStudio's own five recorded poses against its calibration.xml and the
authors' skull cloud."""

from __future__ import annotations

import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest

from cli_runs import assert_error
from rangekit.formats.layouts import LAYOUTS, tool_frames

LAYOUT = LAYOUTS["slstudio:calibration"]


def _record(folder: Path, frames, *, size=None) -> Path:
    """A pose folder of SLStudio's frames (``frameSeq_NN.bmp``), each resized to ``size`` (W, H) if given."""
    folder.mkdir(parents=True)
    for k, image in enumerate(frames):
        assert cv2.imwrite(str(folder / f"frameSeq_{k:02d}.bmp"), image if size is None else cv2.resize(image, size))
    return folder


@pytest.fixture
def boardless(tmp_path):
    """Three poses of a 64x40 projector seen pixel for pixel, without a board."""
    frames = tool_frames(LAYOUT, 64, 40)
    return [_record(tmp_path / f"seq{i}", frames) for i in range(1, 4)]


def _calibrate(cli, tmp_path, folders, *extra):
    return cli("calibrate", "--captures", *folders, "--pattern", "slstudio:calibration", "--projector", "64x40",
               "--cols", "14", "--rows", "10", "--square-mm", "10", "--out", tmp_path / "rig.json", *extra)


def test_options_of_captures_are_checked_before_any_work(cli, tmp_path, boardless):
    run = cli("calibrate", "--pattern", "slstudio:calibration", "--out", tmp_path / "rig.json")
    assert_error(run, 2, "--pattern", "only with --captures")
    run = cli("calibrate", "--captures", *boardless, "--projector", "64x40", "--out", tmp_path / "rig.json")
    assert_error(run, 2, "--captures", "--pattern", "slstudio:calibration")
    run = cli("calibrate", "--captures", *boardless, "--pattern", "slstudio:calibration", "--out",
              tmp_path / "rig.json")
    assert_error(run, 2, "--captures", "--projector", "WxH")
    assert_error(_calibrate(cli, tmp_path, boardless, "--rig", tmp_path / "x.json"), 2, "--rig", "not with --captures")
    run = cli("calibrate", "--captures", *boardless, "--pattern", "slstudio:2x3", "--projector", "64x40",
              "--out", tmp_path / "rig.json")
    assert_error(run, 2, "slstudio:2x3", "only the projector's columns", "columns and rows")
    assert_error(_calibrate(cli, tmp_path, boardless[:2]), 2, "--captures", "2 folder(s)", "at least 3")
    assert_error(_calibrate(cli, tmp_path, [*boardless[:2], boardless[0] / "frameSeq_00.bmp"]), 2,
                 "frameSeq_00.bmp", "expected a folder", "found a file")
    assert not (tmp_path / "rig.json").exists() and not (tmp_path / "coverage.png").exists()


def test_a_folder_that_is_not_the_layout_is_one_line(cli, tmp_path):
    frames = tool_frames(LAYOUT, 64, 40)
    good = [_record(tmp_path / f"seq{i}", frames) for i in (1, 2)]
    short = _record(tmp_path / "short", frames[:6])                     # a 2x3 capture, not a calibration
    assert_error(_calibrate(cli, tmp_path, [*good, short]), 1, "short", "12 frames of slstudio:calibration",
                 "frameSeq_06.bmp missing and 5 more")
    extra = _record(tmp_path / "extra", frames + frames[:1])
    assert_error(_calibrate(cli, tmp_path, [*good, extra]), 1, "extra", "found more (frameSeq_12.bmp)",
                 "projector size")
    other = _record(tmp_path / "other", frames, size=(80, 50))           # another camera's images
    assert_error(_calibrate(cli, tmp_path, [*good, other]), 1, "other", "80x50", "64x40", "same camera")
    mixed = _record(tmp_path / "mixed", frames)
    cv2.imwrite(str(mixed / "frameSeq_07.bmp"), cv2.resize(frames[7], (80, 50)))
    assert_error(_calibrate(cli, tmp_path, [*good, mixed]), 1, "frameSeq_07.bmp")
    assert not (tmp_path / "rig.json").exists()


def test_poses_without_a_board_are_named_and_too_few_left_is_one_line(cli, tmp_path, boardless):
    dark = _record(tmp_path / "dark", [np.zeros((40, 64), np.uint8)] * 12)   # the projector was off
    run = _calibrate(cli, tmp_path, [*boardless, dark])
    line = assert_error(run, 1, "only 0 of 4 board poses usable, at least 3 needed", "seq1: rejected: board not "
                        "found", "dark: rejected: not decoded")
    assert "whole or not at all" in line
    for name in ("seq1", "seq2", "seq3"):
        assert f"{name}: rejected: board not found" in run.err
    assert "dark: rejected: not decoded: no pixel is lit" in run.err
    assert not (tmp_path / "rig.json").exists()


# ------------------------------------------------------------------------------- the simulator's truth
@pytest.mark.slow
def test_simulated_recordings_give_back_the_true_rig(cli, tmp_path):
    """Eight board poses of SLStudio's 9 x 13-corner board (a symmetric one) and one with the board out of view,
    recorded in slstudio:calibration by the simulated rig (a linear projector: a one-period cue under the
    simulator's gamma 2.2 picks the wrong fine period, as it would in SLStudio) and calibrated with --captures.
    Measured: focal lengths within 0.025%, principal points 0.14 and 0.26 px, baseline 0.022%, the projector's
    position 0.06 mm and rotation 0.009 deg from the truth."""
    from rangekit.boards import Board
    from rangekit.calib.procedure import compare_rigs
    from rangekit.geometry import make_T
    from rangekit.rig.rig_file import load_rig
    from rangekit.sim.devices.sim_rig import default_rig
    from rangekit.sim.imaging.render import ImagingModel
    from rangekit.sim.writers.calibration import board_poses, write_layout_poses

    truth = default_rig()
    board = Board(cols=14, rows=10, square=0.014)
    poses = board_poses(truth, board, 8, seed=0)
    poses.insert(2, make_T(t=np.array([0.3, 0.0, 0.0])) @ poses[2])      # out of view: no board found
    folders = write_layout_poses(tmp_path / "recorded", truth, board, poses, LAYOUT, seed=0,
                                 imaging=ImagingModel(gamma=1.0))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        run = cli("calibrate", "--captures", *folders, "--pattern", "slstudio:calibration", "--projector",
                  f"{truth.projector.width}x{truth.projector.height}", "--cols", "14", "--rows", "10",
                  "--square-mm", "14", "--out", tmp_path / "rig.json")
    assert run.code == 0, run.err
    assert "pose_03: rejected: board not found" in run.out and "board poses: 8 of 9 kept" in run.out
    assert "pose_03        not used: board not found" in run.out.split("per board pose")[1]   # in the table
    dev = compare_rigs(load_rig(tmp_path / "rig.json"), truth)
    print("\n", dev)
    for device in ("camera", "projector"):
        for key in ("fx", "fy", "cx", "cy"):
            assert abs(dev[device][key]) < 0.1, (device, key, dev[device])
        assert dev[device]["pp_px"] < 1.0, dev[device]
    assert abs(dev["baseline_pct"]) < 0.1 and dev["translation_mm"] < 0.2 and dev["rotation_deg"] < 0.05, dev
    assert (tmp_path / "coverage.png").is_file()
