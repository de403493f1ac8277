"""The simulator's moving object during a capture (issue 38 item 3, the truth side): each kind's offsets, and a slip
whose frames are those of the still object before it and of the moved object after it."""

from __future__ import annotations

import numpy as np
import pytest

from rangekit.coded.patterns import make_pattern_spec
from rangekit.errors import SceneError
from rangekit.sim import SimRig, default_scene
from rangekit.sim.devices.motion import Motion, capture_moving
from rangekit.sim.scene.passes import pass_scene
from support.small_rigs import small_projector_rig


def test_each_kind_moves_as_documented():
    t = np.arange(10)
    assert Motion("slip", 5e-4, at_frame=4).offset_m(t).tolist() == [0.0] * 4 + [5e-4] * 6
    vib = Motion("vibration", 1e-4, period_frames=4).offset_m(t)
    assert np.allclose(vib, 1e-4 * np.sin(np.pi * t / 2), atol=1e-20) and abs(vib[1] - 1e-4) < 1e-20
    breath = Motion("breathing", 2e-3, period_frames=8).offset_m(t)
    assert breath[0] == 0 and breath[4] == pytest.approx(2e-3) and breath[8] == pytest.approx(0, abs=1e-18)
    T = Motion("slip", 5e-4, direction=(0, 3, 4), at_frame=1).motion(2)
    assert np.allclose(T[:3, 3], [0, 3e-4, 4e-4]) and np.allclose(T[:3, :3], np.eye(3))
    for bad in (dict(kind="drift", amplitude_m=1e-3), dict(kind="slip", amplitude_m=np.nan),
                dict(kind="slip", amplitude_m=1e-3, direction=(0, 0, 0)), dict(kind="vibration", amplitude_m=1e-3,
                                                                               period_frames=0)):
        with pytest.raises(SceneError, match="^motion: "):
            Motion(**bad)


def test_a_slip_shows_the_still_object_then_the_moved_one():
    spec = make_pattern_spec("graycode", (320, 200))
    frames = list(spec.frames())
    rig = small_projector_rig()
    half = len(frames) // 2
    moving = SimRig(default_scene("lumpy"), rig, seed=5)
    got, offsets = capture_moving(moving, frames, Motion("slip", 5e-4, at_frame=half))
    assert offsets.tolist() == [0.0] * half + [5e-4] * (len(frames) - half)
    still = SimRig(default_scene("lumpy"), rig, seed=5).capture_sequence(frames)
    assert all(np.array_equal(a, b) for a, b in zip(got[:half], still[:half]))      # byte for byte before it
    moved_sim = SimRig(pass_scene(default_scene("lumpy"), Motion("slip", 5e-4).motion(0)), rig, seed=5)
    moved = moved_sim.capture_sequence(frames)
    # After it: the moved object's frames, up to the noise (its stream differs): no pixel off by 30 grey levels
    # (about 10 sigma of the noise), where against the unmoved object the moved stripe edges and outline are.
    far = lambda a, b: int(np.count_nonzero(np.abs(a.astype(int) - b.astype(int)) > 30))   # noqa: E731
    assert sum(far(g, m) for g, m in zip(got[half:], moved[half:])) == 0
    assert sum(far(g, s) for g, s in zip(got[half:], still[half:])) > 200     # measured 376 (320 x 256 camera)
    assert far(moving.capture_sequence(frames[:1])[0], still[0]) == 0        # the scene put back


def test_a_rolling_shutter_sees_a_slip_during_a_frames_readout_in_its_lower_rows():
    """Readout over one frame, a slip at the middle of frame ``half``'s readout: frames before it are the still
    capture byte for byte; that frame's top rows are still, its lower rows the moved object's (up to the noise);
    the frames after it are the moved object's."""
    spec = make_pattern_spec("graycode", (320, 200))
    frames = list(spec.frames())
    rig = small_projector_rig()
    half = len(frames) // 2
    motion = Motion("slip", 2e-3, at_frame=half + 0.5)
    got, offsets = capture_moving(SimRig(default_scene("lumpy"), rig, seed=5), frames, motion, readout_frames=1.0,
                                  band_rows=16)
    assert offsets.tolist() == [0.0] * (half + 1) + [2e-3] * (len(frames) - half - 1)
    still = SimRig(default_scene("lumpy"), rig, seed=5).capture_sequence(frames)
    moved = SimRig(pass_scene(default_scene("lumpy"), Motion("slip", 2e-3).motion(0)), rig, seed=5).capture_sequence(
        frames)
    assert all(np.array_equal(a, b) for a, b in zip(got[:half], still[:half]))
    far = lambda a, b: int(np.count_nonzero(np.abs(a.astype(int) - b.astype(int)) > 30))   # noqa: E731
    H = rig.camera.height
    # Band b's middle row is exposed at half + (16 b + 8) / (H - 1): the bands from H/2 on saw the moved object.
    top, bottom = slice(0, 112), slice(144, H)
    assert np.array_equal(got[half][top], still[half][top])
    assert far(got[half][bottom], moved[half][bottom]) == 0 and far(got[half][bottom], still[half][bottom]) > 100
    assert sum(far(g, m) for g, m in zip(got[half + 1:], moved[half + 1:])) == 0
    with pytest.raises(SceneError, match="readout_frames must be from 0 to 1"):
        capture_moving(SimRig(default_scene("lumpy"), rig, seed=5), frames[:2], motion, readout_frames=2.0)
