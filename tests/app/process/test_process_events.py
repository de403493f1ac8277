"""Processing as a function: ``rk.process(session, options, on_event)`` gives the same files as ``rangekit
process``, and its subscriber sees the stages in order, every view's cloud before the fusion starts, each pair
and each mesh."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

import rangekit as rk
from support.sessions import N_VIEWS
from rangekit.app import events as ev
from rangekit.app.process.options import ProcessOptions
from rangekit.cli import main
from rangekit.errors import OptionError, RangekitError


@pytest.fixture(scope="module")
def processed(tmp_path_factory, reference_session):
    """The small reference session processed twice: by the command line, and by rk.process with a subscriber."""
    root = tmp_path_factory.mktemp("process_events")
    ref = reference_session
    by_cli, by_call = shutil.copytree(ref, root / "cli"), shutil.copytree(ref, root / "call")
    assert main(["-q", "process", str(by_cli), "--no-report"]) == 0
    seen: list = []
    result = rk.process(by_call, rk.ProcessOptions(report=False), on_event=seen.append)
    return by_cli, by_call, result, seen


@pytest.mark.slow
def test_the_call_writes_what_the_command_writes(processed):
    by_cli, by_call, result, _ = processed
    for name in ("mesh.ply", "mesh_watertight.ply", "merged.ply", "poses.json"):
        assert (by_cli / name).read_bytes() == (by_call / name).read_bytes(), name
    summary = json.loads((by_cli / "summary.json").read_text())
    assert result.accuracy is not None and result.accuracy.to_dict() == summary["accuracy"]   # the simulator's truth, the same
    assert np.array_equal(result.T_world_view, np.array(summary["T_world_view"]))
    assert json.loads((by_call / "summary.json").read_text())["accuracy"] == summary["accuracy"]


@pytest.mark.slow
def test_every_view_cloud_arrives_before_the_fusion(processed):
    _, _, result, seen = processed
    decoded = [e for e in seen if isinstance(e, ev.ViewDecoded)]
    assert [e.index for e in decoded] == list(range(N_VIEWS))
    assert [len(e.cloud) for e in decoded] == result.n_points
    fuse_start = seen.index(ev.StageStarted("fuse"))
    assert all(seen.index(e) < fuse_start for e in decoded)


@pytest.mark.slow
def test_stages_pairs_and_meshes_are_announced(processed):
    by_cli, by_call, result, seen = processed
    started = [e.stage for e in seen if isinstance(e, ev.StageStarted)]
    finished = [e.stage for e in seen if isinstance(e, ev.StageFinished)]
    assert started[:3] == ["decode", "register", "fuse"] and sorted(started) == sorted(finished)
    assert list(result.seconds) == list(dict.fromkeys(started))
    pairs = [e for e in seen if isinstance(e, ev.PairRegistered)]
    assert len(pairs) == len(result.edges) and sum(p.accepted for p in pairs) >= N_VIEWS - 1
    meshes = {e.kind: e for e in seen if isinstance(e, ev.MeshReady)}
    assert set(meshes) == {"observed", "watertight"}
    assert meshes["observed"].path == by_call / "mesh.ply"
    assert len(meshes["watertight"].mesh.vertices) == result.watertight_mesh.vertices
    assert any(isinstance(e, ev.Progress) for e in seen)
    assert not any(isinstance(e, ev.JobFailed) for e in seen)


def test_a_failure_is_announced_then_raised(tmp_path):
    seen: list = []
    (tmp_path / "session.json").write_text("{}")
    with pytest.raises(RangekitError):
        rk.process(tmp_path, on_event=seen.append)
    assert seen and isinstance(seen[-1], ev.JobFailed)


@pytest.mark.parametrize("bad, what", [({"fusion": "marching"}, "fusion"), ({"method": "plane"}, "method"),
                                       ({"table_margin": float("nan")}, "table_margin"),
                                       ({"report": "yes"}, "report")])
def test_options_are_checked_in_one_place(bad, what):
    with pytest.raises(OptionError, match=f"^{what}: expected "):
        ProcessOptions(**bad)
