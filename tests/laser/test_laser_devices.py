"""The simulated rig's line lasers as devices: the turntable board switches them, the camera
sees the one that is on, the same state gives the same bytes, ground truth is the LaserView's."""

from __future__ import annotations

import numpy as np
import pytest

from rangekit.errors import SceneError
from rangekit.sim import SimRig, default_scene
from rangekit.sim.laser.frames import LaserView
from rangekit.sim.laser.rig import laser_rig


@pytest.fixture(scope="module")
def small_laser_rig():
    from dataclasses import replace

    rig = laser_rig()
    return replace(rig, cameras=(rig.camera.resized(320, 256),))


def test_the_camera_sees_the_laser_the_board_switched_on(small_laser_rig):
    sim = SimRig(default_scene("lumpy"), small_laser_rig, seed=3, light="laser")
    sim.turntable.rotate_to(np.radians(30))
    off = sim.camera.capture()
    sim.turntable.laser(2, True)
    lit = sim.camera.capture()
    view = LaserView(default_scene("lumpy"), sim.rig, np.radians(30), imaging=sim.imaging, seed=3, ambient_scale=4)
    k = sim.laser_index(2)
    assert sim.rig.lasers[k].switch == 2
    assert np.array_equal(off, view.off()) and np.array_equal(lit, view.frame(k).image)
    diff = lit.astype(float) - off.astype(float)
    diff = diff.sum(axis=2) if diff.ndim == 3 else diff
    rows, cols = view.truth_pixels(k)[0].T
    assert len(rows) > 50 and np.median(diff[rows, cols]) > 20 * np.std(diff[diff < np.percentile(diff, 90)])
    # The same state again: the same bytes (a resumed scan records what an uninterrupted one did).
    sim.turntable.laser(2, False)
    sim.turntable.rotate_to(0.0)
    sim.turntable.rotate_to(np.radians(30))
    assert np.array_equal(sim.camera.capture(), off)


def test_two_lasers_at_once_or_an_unknown_laser_are_refused(small_laser_rig):
    sim = SimRig(default_scene("sphere"), small_laser_rig, light="laser")
    sim.turntable.laser(1, True)
    sim.turntable.laser(2, True)
    with pytest.raises(SceneError, match=r"one laser at a time; lasers \[1, 2\] are on"):
        sim.camera.capture()
    with pytest.raises(SceneError, match="laser 5 is not in the rig file's lasers"):
        sim.laser_index(5)


def test_a_laser_rig_needs_lasers():
    from rangekit.sim import default_rig

    with pytest.raises(SceneError, match="has no lasers"):
        SimRig(default_scene("sphere"), default_rig(), light="laser")
