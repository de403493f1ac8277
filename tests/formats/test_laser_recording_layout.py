"""Laser recording layouts (rangekit.formats.layouts.laser): frames by numeric name, the per-step table, and bad
input as one line naming the folder or file."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rangekit.errors import FileFormatError, UsageError
from rangekit.formats.layouts.laser import (LASER_LAYOUTS, STEPS_FILE, read_laser_recording, read_step_frames,
                                            steps_table_text)
from rangekit.io import write_png


def _frames(folder, names, value=0):
    folder.mkdir(parents=True, exist_ok=True)
    for i, name in enumerate(names):
        write_png(folder / name, np.full((4, 6), value + i, np.uint8))


def test_folders_layout_reads_steps_in_numeric_order(tmp_path):
    names = ["1.png", "2.png", "10.png"]            # lexicographic order would put 10 before 2
    for kind, value in (("off", 0), ("laser0", 50), ("laser1", 100)):
        _frames(tmp_path / kind, names, value)
    rec = read_laser_recording(tmp_path, "laser:folders", step_deg=1.5)
    assert (rec.n_lasers, rec.has_off, len(rec.steps)) == (2, True, 3)
    assert [s.lasers[1].name for s in rec.steps] == names
    assert np.allclose(np.degrees(rec.angles), [0, 1.5, 3.0])
    off, frames = read_step_frames(rec.steps[2])
    assert off[0, 0] == 2 and frames[0][0, 0] == 52 and frames[1][0, 0] == 102
    assert "3 steps of 2 laser(s) and the laser-off frame" in rec.line()


def test_folders_layout_without_off_frames_and_one_laser(tmp_path):
    _frames(tmp_path / "laser0", ["a0.png", "a1.png"])
    rec = read_laser_recording(tmp_path, "laser:folders", step_deg=-90)
    assert (rec.n_lasers, rec.has_off) == (1, False)
    assert rec.steps[0].off is None and read_step_frames(rec.steps[0])[0] is None


def test_interleaved_layout_and_steps_table(tmp_path):
    _frames(tmp_path, [f"{k}.png" for k in range(6)])
    (tmp_path / STEPS_FILE).write_text(steps_table_text([0.0, 7.5]))
    rec = read_laser_recording(tmp_path, "laser:off-laser0-laser1")
    assert [s.off.name for s in rec.steps] == ["0.png", "3.png"]
    assert [p.name for p in rec.steps[1].lasers] == ["4.png", "5.png"]
    assert rec.angles[1] == pytest.approx(math.radians(7.5)) and STEPS_FILE in rec.angles_from
    assert set(LASER_LAYOUTS) >= {"laser:folders", "laser:off-laser0", "laser:laser0-laser1"}


@pytest.mark.parametrize("table, expected", [
    ("step,angle_deg\n0,0\n2,10\n", "no row for step 1; expected one row"),
    ("0,0\n1,x\n2,3\n", ":2: expected 'step,angle_deg'"),
    ("0,0\n1,1\n2,2\n3,3\n", ":4: step 3: the recording has 3 steps"),
    ("0,0\n0,1\n1,1\n2,2\n", ":2: step 0 given twice"),
])
def test_bad_steps_table_is_one_line_naming_the_file(tmp_path, table, expected):
    _frames(tmp_path, [f"{k}.png" for k in range(6)])
    (tmp_path / STEPS_FILE).write_text(table)
    with pytest.raises(FileFormatError) as err:
        read_laser_recording(tmp_path, "laser:laser0-laser1")
    assert str(tmp_path / STEPS_FILE) in str(err.value) and expected in str(err.value)
    assert "\n" not in str(err.value)


def test_bad_folders_are_one_line(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(FileFormatError, match="no frames: expected the subfolders of laser:folders, laser0/"):
        read_laser_recording(empty, "laser:folders", step_deg=1)
    with pytest.raises(FileFormatError, match=r"empty: no frames: expected the images of laser:off-laser0 "):
        read_laser_recording(empty, "laser:off-laser0", step_deg=1)
    odd = tmp_path / "odd"
    _frames(odd, [f"{k}.png" for k in range(5)])
    with pytest.raises(FileFormatError, match=r"5 frames \(0.png ... 4.png\) are not a whole number of steps of 3"):
        read_laser_recording(odd, "laser:off-laser0-laser1", step_deg=1)
    uneven = tmp_path / "uneven"
    _frames(uneven / "laser0", ["0.png", "1.png"])
    _frames(uneven / "laser1", ["0.png"])
    with pytest.raises(FileFormatError, match=r"one frame per step in each of laser0/, laser1/ \(2 steps\), found "
                                              r"laser1/ holds 1"):
        read_laser_recording(uneven, "laser:folders", step_deg=1)
    with pytest.raises(FileFormatError, match="expected a folder of laser frames"):
        read_laser_recording(tmp_path / "missing", "laser:folders", step_deg=1)


def test_step_angle_given_once(tmp_path):
    _frames(tmp_path, ["0.png", "1.png"])
    with pytest.raises(UsageError, match="no steps.csv and no step angle: give --step-deg"):
        read_laser_recording(tmp_path, "laser:laser0")
    with pytest.raises(UsageError, match="expected a finite, non-zero angle"):
        read_laser_recording(tmp_path, "laser:laser0", step_deg=0.0)
    (tmp_path / STEPS_FILE).write_text("0,0\n1,5\n")
    with pytest.raises(UsageError, match="gives each step's angle; give one of them"):
        read_laser_recording(tmp_path, "laser:laser0", step_deg=5.0)
    with pytest.raises(UsageError, match="not a laser recording layout"):
        read_laser_recording(tmp_path, "laser:nope")
