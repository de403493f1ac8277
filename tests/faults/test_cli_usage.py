"""Bad options end with exit 2 and one ``rangekit: error:`` line naming the option and the found value,
before any work or any file is written."""

from __future__ import annotations

import pytest

from support.cli_runs import assert_error


@pytest.mark.parametrize("args, mentions", [
    (["scan", "--seed", "-1"], ["--seed", "'-1'"]),
    (["scan", "--views", "0"], ["--views", "'0'"]),
    (["scan", "--views", "ten"], ["--views", "'ten'"]),
    (["register", "a.ply", "b.ply", "--voxel-mm", "0"], ["--voxel-mm", "'0'"]),
    (["register", "a.ply", "b.ply", "--voxel-mm", "-3"], ["--voxel-mm", "'-3'"]),
    (["register", "a.ply", "b.ply", "--voxel-mm", "nan"], ["--voxel-mm", "'nan'"]),
    (["render", "m.ply", "--size", "100000x100000"], ["--size", "100000x100000"]),
    (["render", "m.ply", "--elevation", "inf"], ["--elevation", "'inf'"]),
    (["calibrate", "--cols", "1000", "--rows", "1000"], ["--cols", "'1000'"]),
    (["calibrate", "--square-mm", "0"], ["--square-mm", "'0'"]),
    (["devices", "--timeout", "nan"], ["--timeout", "'nan'"]),
    (["devices", "--timeout", "-1"], ["--timeout", "'-1'"]),
    (["mesh", "c.ply", "--depth", "30"], ["--depth", "'30'"]),
    (["sim", "render", "--sensor", "tof", "--steps", "100000000"], ["--steps", "'100000000'"]),
    (["sim", "render", "--sensor", "tof", "--near", "-1"], ["--near", "'-1'"]),
    (["stereo", "l.png", "r.png", "--rig", "r.json", "--alpha", "2"], ["--alpha", "'2'"]),
    (["tof", "raw", "--max-range", "0"], ["--max-range", "'0'"]),
])
def test_a_bad_option_value_is_a_usage_error(cli, tmp_path, args, mentions):
    run = cli(*args, *(["--out", tmp_path / "out"] if args[0] not in ("devices",) else []))
    assert_error(run, 2, *mentions)
    assert not (tmp_path / "out").exists()


def test_resuming_with_a_negative_seed_is_refused_before_the_session_is_touched(cli, tmp_path):
    run = cli("scan", "--out", tmp_path / "s", "--seed", "-1", "--views", "2")
    assert_error(run, 2, "--seed")
    assert not (tmp_path / "s").exists()


def test_register_turntable_prior_with_nan_is_a_usage_error(cli, tmp_path):
    scans = []
    for k in range(2):
        p = tmp_path / f"s{k}.xyz"
        p.write_text("0 0 0\n1 0 0\n0 1 0\n")
        scans.append(p)
    run = cli("register", *scans, "--init", "turntable:0,0,1:nan", "--out", tmp_path / "r")
    assert_error(run, 2, "--init", "turntable:0,0,1:nan", "finite")
    assert not (tmp_path / "r").exists()
