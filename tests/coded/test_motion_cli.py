"""``rangekit sim render --motion-mm`` and ``rangekit decode`` of the capture (issue 38 item 3): the motion mask,
the refusal naming the frames, and a still capture that passes (the small rig: a 320x256 camera, a 320x200 projector)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from support.cli_runs import assert_error
from rangekit.rig.rig_file import save_rig
from support.small_rigs import small_projector_rig


def test_a_slipped_capture_is_flagged_and_refused_by_name_a_still_one_is_not(cli, tmp_path):
    save_rig(small_projector_rig(), tmp_path / "rig.json")
    moving, still = tmp_path / "moving", tmp_path / "still"
    assert cli("sim", "render", "--rig", tmp_path / "rig.json", "--motion-mm", "2", "--out", moving).code == 0
    assert cli("sim", "render", "--rig", tmp_path / "rig.json", "--out", still).code == 0
    record = json.loads((moving / "capture.json").read_text())
    n = record["n_frames"]
    assert record["motion"]["kind"] == "slip" and record["motion"]["amplitude_m"] == 0.002
    assert record["frame_offsets_m"] == [0.0] * (n // 2) + [0.002] * (n - n // 2)
    run = cli("decode", moving, "--pattern", moving / "patterns.json", "--out", tmp_path / "m.npz")
    line = assert_error(run, 1, "the object moved during the capture", "frames after: ", "max_motion")
    names = line.split("frames after: ")[1].split(")")[0].split(", ")
    frames = json.loads((moving / "patterns.json").read_text())
    assert names and names[0].startswith(("col_b", "row_b"))
    run = cli("decode", moving, "--pattern", moving / "patterns.json", "--max-motion", "none", "--out", tmp_path / "m.npz")
    assert run.code == 0 and "motion=" in run.out
    maps = np.load(tmp_path / "m.npz")
    assert maps["motion"].mean() > 0.02 and not np.any(np.isfinite(maps["proj_col"][maps["motion"]]))
    # reconstruct and rk.reconstruct refuse what decode refuses (issue 48: they made a cloud of it)
    run = cli("reconstruct", moving, "--out", tmp_path / "moving.ply")
    assert_error(run, 1, "the object moved during the capture", "max_motion")
    assert not (tmp_path / "moving.ply").exists()
    import rangekit as rk
    from rangekit.errors import MotionError

    with pytest.raises(MotionError, match="the object moved during the capture"):
        rk.reconstruct(moving)
    assert cli("reconstruct", moving, "--max-motion", "none", "--out", tmp_path / "moving.ply").code == 0
    assert cli("reconstruct", still, "--out", tmp_path / "still.ply").code == 0
    assert cli("decode", still, "--pattern", still / "patterns.json", "--out", tmp_path / "s.npz").code == 0
    calm = np.load(tmp_path / "s.npz")
    assert calm["motion"].sum() < 0.005 * np.isfinite(calm["proj_col"]).sum()     # 0.21% here (0.084% on the default rig)
    assert frames["method"] == "graycode"
    bad = cli("decode", still, "--pattern", still / "patterns.json", "--max-motion", "150%", "--out", tmp_path / "x.npz")
    assert bad.code == 2 and "percentage from 0 to 100" in bad.err
    rolling = tmp_path / "rolling"
    assert cli("sim", "render", "--rig", tmp_path / "rig.json", "--motion-mm", "2", "--readout-frames", "1",
               "--out", rolling).code == 0
    assert json.loads((rolling / "capture.json").read_text())["readout_frames"] == 1.0
    run = cli("sim", "render", "--rig", tmp_path / "rig.json", "--motion-mm", "2", "--readout-frames", "3",
              "--out", tmp_path / "r3")
    assert_error(run, 2, "--readout-frames", "a number in 0..1", "'3'")   # an option error (issue 48), was exit 1
