"""A command whose --out holds another command's set of files (issue 34, "output into a session or a finished
result"): refused by name, nothing changed; with --force the other set is replaced as a whole, and files that
belong to no set stay. rangekit.formats.output_sets."""

from __future__ import annotations

import os
import time

import numpy as np
import pytest

from support.cli_runs import assert_error
from rangekit.errors import UsageError
from rangekit.formats.clouds import save_cloud
from rangekit.formats.output_sets import claim_folder, set_in
from rangekit.surface.cloud import PointCloud


def _tree(folder):
    return {p.relative_to(folder).as_posix(): (p.read_bytes() if p.is_file() else None)
            for p in sorted(folder.rglob("*"))}


def _processed(session):
    """The reference session with the files processing leaves (a processed session)."""
    for name in ("summary.json", "poses.json", "merged.ply", "mesh.ply", "report.html"):
        (session / name).write_text("{}" if name.endswith(".json") else "old run")
    return session


def test_the_set_in_a_folder_is_found_by_its_marker(tmp_path):
    assert set_in(tmp_path) is None
    (tmp_path / "poses.json").write_text("{}")
    assert set_in(tmp_path).name == "registration"
    (tmp_path / "session.json").write_text("{}")
    assert set_in(tmp_path).name == "session"    # a processed session has poses.json too


def test_claim_refuses_another_set_and_force_replaces_only_its_members(tmp_path):
    (tmp_path / "session.json").write_text("{}")
    (tmp_path / "view_000").mkdir()
    (tmp_path / "view_000" / "000.png").write_bytes(b"png")
    (tmp_path / "rig.json").write_text("{}")
    (tmp_path / "notes.txt").write_text("mine")
    past = time.time() - 10
    for p in tmp_path.rglob("*"):
        os.utime(p, (past, past))
    with pytest.raises(UsageError, match=r"holds a scan session \(rangekit scan\) \(session.json\).*--force"):
        claim_folder(tmp_path, "check", force=False)
    replace = claim_folder(tmp_path, "check", force=True)
    (tmp_path / "rig.json").write_text('{"new": 1}')      # the check writes its own rig.json
    (tmp_path / "check.json").write_text("{}")
    assert sorted(replace()) == ["session.json", "view_000"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["check.json", "notes.txt", "rig.json"]
    assert (tmp_path / "rig.json").read_text() == '{"new": 1}'


def test_a_rerun_removes_what_the_earlier_run_wrote_and_this_one_did_not(tmp_path):
    for name in ("poses.json", "merged.ply", "mesh.ply"):
        (tmp_path / name).write_text("old")
        os.utime(tmp_path / name, (time.time() - 10,) * 2)
    replace = claim_folder(tmp_path, "registration", force=False)
    (tmp_path / "poses.json").write_text("new")
    (tmp_path / "merged.ply").write_text("new")           # --no-mesh: no mesh.ply this time
    assert replace() == ["mesh.ply"]


def test_check_into_a_session_is_refused_and_changes_nothing(cli, tmp_session):
    before = _tree(tmp_session)
    run = cli("check", "--out", tmp_session)
    assert_error(run, 2, f"--out {tmp_session}", "a scan session", "session.json", "--force")
    assert _tree(tmp_session) == before


def test_sim_render_into_a_session_is_refused_then_force_replaces_it(cli, tmp_session):
    (tmp_session / "notes.txt").write_text("mine")
    before = _tree(tmp_session)
    run = cli("sim", "render", "--sensor", "stereo", "--size", "160x100", "--out", tmp_session)
    assert_error(run, 2, "a scan session", "--force")
    assert _tree(tmp_session) == before
    run = cli("sim", "render", "--sensor", "stereo", "--size", "160x100", "--out", tmp_session, "--force")
    assert run.code == 0, run.err
    names = sorted(p.name for p in tmp_session.iterdir())
    assert names == ["capture.json", "ground_truth.npz", "left.png", "notes.txt", "preview.png", "rig.json",
                     "right.png"], names


def _scan_pair(tmp_path):
    rng = np.random.default_rng(0)
    p = rng.normal(size=(3000, 3))
    p = 0.05 * p / np.linalg.norm(p, axis=1, keepdims=True) * (1 + 0.2 * np.sin(5 * p[:, :1]) * np.cos(3 * p[:, 1:2]))
    paths = [tmp_path / "a.xyz", tmp_path / "b.xyz"]
    save_cloud(paths[0], PointCloud(p))
    save_cloud(paths[1], PointCloud(p + [0.001, 0.0, 0.0]))
    return paths


@pytest.mark.slow
def test_register_into_a_processed_session_is_refused_then_force_replaces_the_session(cli, tmp_session, tmp_path):
    session = _processed(tmp_session)
    before = _tree(session)
    paths = _scan_pair(tmp_path)
    run = cli("register", *paths, "--init", "none", "--no-mesh", "--out", session)
    assert_error(run, 2, "a scan session", "session.json", "--force")
    assert _tree(session) == before
    run = cli("register", *paths, "--init", "none", "--no-mesh", "--out", session, "--force")
    assert run.code == 0, run.err
    assert sorted(p.name for p in session.iterdir()) == ["merged.ply", "poses.json"]
    assert "removed the earlier" in run.out
