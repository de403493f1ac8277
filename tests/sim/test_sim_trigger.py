"""The simulated projector's VSYNC triggering its camera (sim/devices/trigger.py): no pattern delay, the exposure
inside the pattern's display, a trigger count on each frame, a missed trigger."""

from dataclasses import replace

import numpy as np
import pytest

from rangekit.errors import DeviceError, MissedTrigger, SceneError
from rangekit.rig.camera_controls import CameraControls
from rangekit.sim import SimRig, default_scene
from support.small_rigs import small_rig


def _triggered(refresh_hz=None, latency_s=0.05) -> SimRig:
    rig = small_rig()
    devices = {} if refresh_hz is None else {"projector": {"type": "sim", "refresh_hz": refresh_hz}}
    rig = replace(rig, capture={"trigger": "projector"}, devices=devices)
    return SimRig(default_scene("lumpy"), rig, seed=1, latency_s=latency_s)


def _patterns(sim: SimRig, n: int) -> list[np.ndarray]:
    W, H = sim.projector.resolution
    return [np.full((H, W), 20 * (k + 1), np.uint8) for k in range(n)]


@pytest.mark.parametrize("exposure_us, hold", [(16_667, 1), (33_333, 2), (5_000, 1)])
def test_each_frame_is_exposed_inside_its_patterns_display_and_counted(exposure_us, hold):
    sim = _triggered()
    sim.camera.set_controls(CameraControls(exposure_us=exposure_us))
    sim.camera.arm_trigger()
    period = 1 / 60
    patterns = _patterns(sim, 5)
    for p in patterns:
        sim.projector.show(p)                       # no wait between patterns: one per `hold` refreshes
    assert sim.clock.now() == pytest.approx(4 * hold * period)
    for k, p in enumerate(patterns):
        frame = sim.camera.capture_triggered_deferred(1.0)
        assert frame.trigger == k + 1
        start, end = sim.camera.last_exposure_window
        shown = sim.camera.last_shown_window
        # the exposure inside the pattern's display (within 1 % of a refresh, the refresh check's rule)
        assert shown[0] <= start and end <= shown[1] + 0.01 * period
        assert shown[1] - shown[0] == pytest.approx(hold * period)
        # shown after the projector's latency, at a refresh: 0.05 s is 3 refreshes at 60 Hz
        assert start == pytest.approx(k * hold * period + 3 * period)
    assert sim.clock.now() == pytest.approx((4 * hold + 3 + hold) * period)


def test_the_triggered_frame_is_the_untriggered_capture_of_its_pattern():
    sim, free = _triggered(), SimRig(default_scene("lumpy"), small_rig(), seed=1)
    sim.camera.arm_trigger()
    patterns = _patterns(sim, 3)
    for p in patterns:
        sim.projector.show(p)
    for p in patterns:
        free.projector.show(p)
        assert np.array_equal(sim.camera.capture_triggered(1.0).image, free.camera.capture())


def test_a_missed_trigger_is_counted_without_a_frame():
    sim = _triggered(refresh_hz=120)
    sim.camera.set_controls(CameraControls(exposure_us=8_333))
    sim.camera.arm_trigger()
    sim.inject_missed_trigger(after=1)
    for p in _patterns(sim, 4):
        sim.projector.show(p)
    assert [sim.camera.capture_triggered_deferred(1.0).trigger for _ in range(3)] == [1, 3, 4]
    t = sim.clock.now()
    with pytest.raises(MissedTrigger, match=r"no triggered frame within 0.5 s \(4 pulse\(s\) counted since it was armed, no frame left\)"):
        sim.camera.capture_triggered_deferred(0.5)
    assert sim.clock.now() == pytest.approx(t + 0.5)
    sim.camera.arm_trigger()                     # re-armed: the count restarts
    sim.projector.show(_patterns(sim, 1)[0])
    assert sim.camera.capture_triggered_deferred(1.0).trigger == 1


def test_triggering_needs_a_triggered_rig_a_locked_exposure():
    free = SimRig(default_scene("lumpy"), small_rig(), seed=1)
    assert free.trigger is None
    with pytest.raises(DeviceError, match="capture.trigger is not 'projector'"):
        free.camera.arm_trigger()
    with pytest.raises(SceneError, match="capture.trigger is 'projector'"):
        free.inject_missed_trigger()
    sim = _triggered()
    sim.camera.set_controls(CameraControls(exposure_us=None, allow_auto_exposure=True))
    with pytest.raises(DeviceError, match="needs a locked exposure"):
        sim.camera.arm_trigger()
