"""Acquisition on a rig whose camera the projector triggers (rig file capture.trigger "projector"): no pattern
delay, every frame's trigger count checked, a missed trigger named and its view taken again, the frames the bytes
of a scan without the fault (issue 50 Deliver 3, issue 51's acceptance "a triggered rig in the simulator")."""

import json
from dataclasses import replace

import pytest

from rangekit.app.acquire.acquire import acquire
from rangekit.app.acquire.triggered import uses_trigger
from rangekit.coded.patterns import make_pattern_spec
from rangekit.errors import ConfigError
from rangekit.formats.sessions.session import CaptureSettings, ScanPlan
from rangekit.laser.sequence import LaserSequence
from rangekit.sim import SimRig, default_scene
from support.sessions import frame_paths, pngs
from support.small_rigs import small_rig

SPEC = make_pattern_spec("graycode", (1280, 800))
PLAN = ScanPlan(n_views=2)


def _rig(trigger: bool):
    rig = small_rig()
    return replace(rig, capture={"pattern_delay_s": 0.1, **({"trigger": "projector"} if trigger else {})})


def _scan(folder, trigger: bool, miss_after: int | None = None, plan: ScanPlan = PLAN):
    rig = _rig(trigger)
    sim = SimRig(default_scene("lumpy"), rig, seed=3)
    if miss_after is not None:
        sim.inject_missed_trigger(after=miss_after)
    said = []
    acquire(sim, rig, SPEC, folder, plan=plan, progress=lambda msg, *a, **k: said.append(msg))
    return sim, said


def test_a_missed_trigger_is_named_the_view_taken_again_and_the_frames_are_those_without_it(tmp_path):
    n = SPEC.n_frames
    sim, _ = _scan(tmp_path / "clean", trigger=True)
    # No pattern delay: each view is its patterns at the projector's pace, 33 ms exposures 2 refreshes at 60 Hz each
    # (no latency here); the rig file's 0.1 s pattern delay is not waited.
    assert sim.clock.now() == pytest.approx(PLAN.n_views * n * 2 / 60)
    assert json.loads((tmp_path / "clean" / "session.json").read_text())["capture"]["pattern_delay_s"] == 0.0
    _, said = _scan(tmp_path / "fault", trigger=True, miss_after=n + 5)     # frame 5 of view 1
    retakes = [m for m in said if "missed" in m]
    assert retakes == [f"view 2/2, frame 5 ({SPEC.frame_names[5]}): camera: the camera missed trigger 6: the frame "
                       "taken for it carries trigger 7; the view is taken again"]
    clean, fault = pngs(tmp_path / "clean"), pngs(tmp_path / "fault")
    assert len(clean) == PLAN.n_views * n and fault == clean
    sha = [json.loads((tmp_path / s / "session.json").read_text())["views"] for s in ("clean", "fault")]
    assert sha[0] == sha[1]
    # The frames are those of an untriggered scan of the same seed and exposure (which waits the pattern delay).
    _scan(tmp_path / "free", trigger=False, plan=ScanPlan(n_views=1))      # view 0 of the same angle
    free = pngs(tmp_path / "free")
    assert free and all(clean[name] == frame for name, frame in free.items())
    assert len(frame_paths(tmp_path / "fault")) == len(clean)


def test_a_triggered_rig_waits_no_pattern_delay():
    assert CaptureSettings.from_rig(_rig(True), hardware=True).pattern_delay_s == 0.0
    assert CaptureSettings.from_rig(_rig(False), hardware=True).pattern_delay_s == 0.1
    assert CaptureSettings.from_rig(small_rig(), hardware=True).pattern_delay_s == 0.1


def test_a_trigger_the_scan_cannot_use_is_refused_before_any_frame(tmp_path):
    sim = SimRig(default_scene("lumpy"), _rig(True), seed=3)
    assert uses_trigger(sim.camera, _rig(True), SPEC) and not uses_trigger(sim.camera, _rig(False), SPEC)
    with pytest.raises(ConfigError, match=r"capture.trigger 'projector': .* a laser scan's lasers send no trigger"):
        uses_trigger(sim.camera, _rig(True), LaserSequence(1))

    class Untriggered:
        calibration = sim.camera.calibration

        def capture(self):
            return sim.camera.capture()

    with pytest.raises(ConfigError, match=r"this camera \(Untriggered\) has no triggered capture; set capture.trigger"):
        uses_trigger(Untriggered(), _rig(True), SPEC)
    sim.camera = Untriggered()
    with pytest.raises(ConfigError, match="no triggered capture"):
        acquire(sim, _rig(True), SPEC, tmp_path / "s", plan=PLAN)
    assert not list((tmp_path / "s").glob("view_*"))


def test_the_scan_option_makes_the_simulators_rig_triggered():
    from rangekit.app.scan.options import ScanOptions
    from rangekit.errors import OptionError

    with pytest.raises(OptionError, match=r"rig r.json says it in its file \(capture.trigger\): leave triggered out"):
        ScanOptions(out="x", rig="r.json", triggered=True)
    with pytest.raises(OptionError, match="a laser scan's lasers send no trigger"):
        ScanOptions(out="x", method="laser", triggered=True)
    with pytest.raises(OptionError, match="expected True or False"):
        ScanOptions(out="x", triggered="yes")


class _Driver:
    """The simulated triggered camera as a driver offers it: ``arm_trigger`` and ``capture_triggered`` only (no
    deferred rendering), as the GenICam driver would."""

    def __init__(self, camera):
        self._camera = camera
        self.calibration = camera.calibration

    def capture(self):
        return self._camera.capture()

    def arm_trigger(self):
        self._camera.arm_trigger()

    def capture_triggered(self, timeout_s):
        return self._camera.capture_triggered(timeout_s)


def test_a_drivers_triggered_frames_are_checked_and_written_the_same(tmp_path):
    rig = _rig(True)
    sim = SimRig(default_scene("lumpy"), rig, seed=3)
    sim.camera = _Driver(sim.camera)
    sim.inject_missed_trigger(after=SPEC.n_frames - 1)      # the last frame of view 0: no frame comes
    said = []
    acquire(sim, rig, SPEC, tmp_path / "driver", plan=PLAN, progress=lambda msg, *a, **k: said.append(msg))
    assert [m for m in said if "trigger" in m] == [
        f"view 1/2, frame {SPEC.n_frames - 1} ({SPEC.frame_names[-1]}): camera: no frame for trigger {SPEC.n_frames}: "
        f"camera (simulated): no triggered frame within 1 s ({SPEC.n_frames} pulse(s) counted since it was armed, no "
        "frame left); the view is taken again"]
    _scan(tmp_path / "clean", trigger=True)
    assert pngs(tmp_path / "driver") == pngs(tmp_path / "clean")
