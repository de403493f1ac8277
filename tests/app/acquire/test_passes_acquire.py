"""Multi-pass scans: the session's passes, the simulated turn-over, resume in pass 2, the prompt."""

import io
import json

import numpy as np
import pytest

from rangekit.app.acquire.acquire import acquire
from rangekit.app.scan.passes import TurnOverNeeded, turn_over_prompt
from rangekit.coded.patterns import make_pattern_spec
from rangekit.errors import ConfigError, DeviceDisconnected
from rangekit.formats.sessions.session import ScanPlan, Session, SimulatorSettings, load_session
from rangekit.geometry import apply_T, rotation_angle
from rangekit.rig.rig_file import Rig
from rangekit.sim import SimRig, default_rig, default_scene
from rangekit.sim.scene.passes import pass_motions, pass_scene, turn_over_motion


def small_rig():
    r = default_rig()
    return Rig(cameras=(r.camera.resized(160, 128),), projector=r.projector, T_world_table=r.T_world_table)


def two_pass_sim(seed=3):
    scene = default_scene("lumpy")
    return SimRig(scene, small_rig(), seed=seed, pass_motions=pass_motions(scene, small_rig(), 2))


def settings(sim):
    return SimulatorSettings("lumpy", 3, pass_motions=tuple(tuple(map(tuple, m.tolist())) for m in sim.pass_motions))


def pngs(folder):
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.glob("view_*/*.png"))}


SPEC = make_pattern_spec("graycode", (1280, 800))
PLAN = ScanPlan(n_views=4, passes=2)


def test_plan_angles_and_passes():
    assert np.allclose(PLAN.angles(), [0, np.pi, 0, np.pi]) and PLAN.view_passes().tolist() == [0, 0, 1, 1]
    one = ScanPlan(n_views=4)
    assert np.allclose(one.angles(), np.arange(4) * np.pi / 2) and one.view_passes().tolist() == [0] * 4


def test_the_simulated_turn_over_is_a_known_rigid_flip_resting_on_the_table():
    scene, rig = default_scene("lumpy"), default_rig()
    F = turn_over_motion(scene, rig)
    R = F[:3, :3]
    assert np.allclose(R @ R.T, np.eye(3), atol=1e-12) and np.isclose(np.linalg.det(R), 1.0)
    assert np.isclose(np.degrees(rotation_angle(R)), 180.0)          # a half-turn...
    assert abs(R[:, 2] @ [0, 0, 1] + 1) < 1e-12                      # ...that puts the top at the bottom
    moved = pass_scene(scene, F).objects[0].world_vertices()
    before = scene.objects[0].world_vertices()
    assert np.isclose(moved[:, 2].min(), 0.0, atol=1e-12)              # resting on the table top
    top = np.argmax(before[:, 2])
    assert np.isclose(moved[top, 2], 0.0, atol=1e-12) or moved[top, 2] < 0.01 * np.ptp(before[:, 2]) + 1e-3
    assert np.allclose(apply_T(F, before), moved, atol=1e-12)
    assert pass_scene(scene, F).objects[1] is scene.objects[1]          # the table does not turn over


def test_two_pass_session_round_trip_and_the_truth_recorded(tmp_path):
    s = two_pass_sim()
    session = acquire(s, small_rig(), SPEC, tmp_path / "s", plan=PLAN, simulator=settings(s))
    data = json.loads((tmp_path / "s" / "session.json").read_text())
    assert data["plan"]["passes"] == 2 and [v["pass"] for v in data["views"]] == [0, 0, 1, 1]
    assert np.allclose(data["simulator"]["pass_motions"][1], s.pass_motions[1])
    loaded = Session.load(tmp_path / "s")
    assert loaded.plan == PLAN and [v.scan_pass for v in loaded.views] == [0, 0, 1, 1]
    assert np.allclose(loaded.simulator.pass_motions, s.pass_motions)
    assert loaded.to_dict() == session.to_dict() == data
    # The second pass images the turned-over object: same angle, other bytes.
    a = pngs(tmp_path / "s")
    assert a["view_000/000.png"] != a["view_002/000.png"]


def test_one_pass_sessions_keep_their_manifest_and_old_ones_read_as_one_pass(tmp_path):
    acquire(SimRig(default_scene("lumpy"), small_rig()), small_rig(), SPEC, tmp_path / "s", plan=ScanPlan(n_views=2))
    data = json.loads((tmp_path / "s" / "session.json").read_text())
    assert "passes" not in data["plan"] and all("pass" not in v for v in data["views"])
    assert "pass_motions" not in data.get("simulator", {})
    s = load_session(tmp_path / "s")
    assert s.plan.passes == 1 and [v.scan_pass for v in s.views] == [0, 0]


@pytest.mark.parametrize("change, match", [
    (lambda d: d["plan"].update(passes=3), r"plan.n_views: expected a multiple of plan.passes \(3\), found 4"),
    (lambda d: d["plan"].update(passes=0), r"plan.passes: expected an integer in 1..8, found 0"),
    (lambda d: d["views"][2].update({"pass": 0}), r"views\[2\].pass: expected 1 \(the plan's pass of view 2\)"),
    (lambda d: d["simulator"]["pass_motions"][1][0].__setitem__(0, 2.0), r"simulator.pass_motions\[1\]: expected a rigid"),
    (lambda d: d["simulator"]["pass_motions"].pop(), r"simulator.pass_motions: expected 2 rigid motions"),
])
def test_bad_passes_in_session_json_are_named(tmp_path, change, match):
    s = two_pass_sim()
    acquire(s, small_rig(), SPEC, tmp_path / "s", plan=ScanPlan(n_views=4, passes=2), simulator=settings(s))
    path = tmp_path / "s" / "session.json"
    data = json.loads(path.read_text())
    change(data)
    path.write_text(json.dumps(data))
    with pytest.raises(ConfigError, match=match):
        Session.load(tmp_path / "s")


def test_a_scan_interrupted_in_pass_2_resumes_in_pass_2_with_the_same_bytes(tmp_path):
    s = two_pass_sim()
    acquire(s, small_rig(), SPEC, tmp_path / "a", plan=PLAN, simulator=settings(s))
    s = two_pass_sim()
    s.inject_fault("camera", after=2 * SPEC.n_frames + 3)      # in view 2, the first of pass 2
    with pytest.raises(DeviceDisconnected):
        acquire(s, small_rig(), SPEC, tmp_path / "b", plan=PLAN, simulator=settings(s))
    assert [v.done for v in load_session(tmp_path / "b").views] == [True, True, False, False]
    s = two_pass_sim()   # a new process: the rig starts in pass 0, resuming turns it over
    session = acquire(s, small_rig(), SPEC, tmp_path / "b", plan=PLAN, resume=True)
    assert all(v.done for v in session.views)
    assert pngs(tmp_path / "b") == pngs(tmp_path / "a")
    with pytest.raises(ConfigError, match="another plan"):
        acquire(two_pass_sim(), small_rig(), SPEC, tmp_path / "b", plan=ScanPlan(n_views=4), resume=True)


class _Tty(io.StringIO):
    def isatty(self):
        return True


def test_turn_over_is_asked_once_per_pass_and_refused_without_a_terminal(tmp_path):
    calls = []
    s = two_pass_sim()
    acquire(s, small_rig(), SPEC, tmp_path / "s", plan=PLAN, simulator=settings(s), turn_over=calls.append)
    assert calls == [1]
    # No terminal: stops after pass 1 is on disk, naming the folder and the command that continues.
    s = two_pass_sim()
    prompt = turn_over_prompt(tmp_path / "h", 2, stdin=io.StringIO(""))
    with pytest.raises(TurnOverNeeded, match=r"h: pass 1 of 2 is done .* not a terminal.*rangekit scan --resume "
                                             r".*h --flipped"):
        acquire(s, small_rig(), SPEC, tmp_path / "h", plan=PLAN, simulator=settings(s), turn_over=prompt)
    assert [v.done for v in load_session(tmp_path / "h").views] == [True, True, False, False]
    # --flipped: the first ask is answered; the scan finishes in pass 2.
    acquire(two_pass_sim(), small_rig(), SPEC, tmp_path / "h", plan=PLAN, resume=True,
            turn_over=turn_over_prompt(tmp_path / "h", 2, flipped=True, stdin=io.StringIO("")))
    assert pngs(tmp_path / "h") == pngs(tmp_path / "s")
    # A terminal: asks, waits for Enter; end of input is refused.
    out = io.StringIO()
    turn_over_prompt("d", 2, stdin=_Tty("\n"), stream=out)(1)
    assert "Turn the object over" in out.getvalue() and "press Enter to scan pass 2" in out.getvalue()
    with pytest.raises(TurnOverNeeded, match="no answer"):
        turn_over_prompt("d", 2, stdin=_Tty(""), stream=io.StringIO())(1)
