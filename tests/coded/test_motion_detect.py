"""Whether a view moved, on a pair of lines in 16 (rangekit.coded.motion.detect), and the guard where the camera does not
resolve the projector's codes (rangekit.coded.motion.check.code_step), against the simulator's knocked object
(SimRig.inject_motion): the same frames still, and the frames from one on of a 0.5 mm knock; a hybrid without its
finest Gray bits checked on its blocks (issue 51)."""

from __future__ import annotations

import numpy as np
import pytest

from rangekit.coded.decode import decode
from rangekit.coded.motion import MAX_MOTION_SHARE, check_motion, detect_motion
from rangekit.coded.motion.check import code_step
from rangekit.coded.patterns import make_pattern_spec
from rangekit.sim import SimRig, default_rig, default_scene
from support.small_rigs import small_projector_rig, small_rig


def _capture(rig, pattern: str, knock_from: int | None = None, mm: float = 0.5, obj: str = "lumpy", **options):
    """(spec, stack (K, H, W), decoded (H, W)) of ``obj`` (the default object); ``knock_from``: frames from this one
    on see the object moved ``mm`` along x (the still capture's decoded pixels are the ones counted); ``options``:
    the pattern's."""
    spec = make_pattern_spec(pattern, (rig.projector.width, rig.projector.height), **options)
    frames = list(spec.frames())
    sim = SimRig(default_scene(obj), rig, seed=5)
    if knock_from is not None:
        T = np.eye(4)
        T[0, 3] = mm * 1e-3
        sim.inject_motion(T, after=knock_from, frames=len(frames) - knock_from)
    stack = np.stack(sim.capture_sequence(frames))
    return spec, stack


@pytest.mark.parametrize("pattern", ["graycode", "hybrid"])
def test_a_knock_is_refused_and_a_still_capture_is_not_on_a_small_rig(pattern):
    """320x256 camera, 320x200 projector (about a camera pixel per code, a code 4x the default rig's): a 2 mm knock
    from col_b2 on (measured 6.0% and 6.3% moved; 5.0% and 5.8% on single lines 8 apart reading every bit, 0.9%
    with the rule of the bits read: issue 47); a still capture 0.0% and 0.0% (0.34% and 0.52% reading every bit)."""
    rig = small_projector_rig()
    spec, still = _capture(rig, pattern)
    decoded = np.isfinite(decode(still, spec).proj_col)
    assert detect_motion(still, spec, decoded).share < 0.5 * MAX_MOTION_SHARE
    _, knocked = _capture(rig, pattern, knock_from=spec.frame_names.index("col_b2"), mm=2.0)
    got = detect_motion(knocked, spec, decoded)
    assert got.share > 2 * MAX_MOTION_SHARE, got.describe()
    assert {"col_b2", "col_b2_inv"} <= set(got.moved_frames), got.moved_frames
    assert not got.mask.any() and got.undersampled == ()


@pytest.mark.slow
def test_a_half_millimetre_knock_on_the_default_rig():
    """The default rig (1280x1024 camera, 1280x800 projector), hybrid patterns: a still capture 0.056% (of the
    issue's < 0.1% false flags; 0.054% before issue 47), a 0.5 mm knock from col_b1 on 10.4% and from col_b3 on
    3.0% (refused over 2%; 12% and 2.4% before)."""
    rig = default_rig()
    spec, still = _capture(rig, "hybrid")
    decoded = np.isfinite(decode(still, spec).proj_col)
    assert detect_motion(still, spec, decoded).share < 0.001
    for bit in ("col_b1", "col_b3"):
        _, knocked = _capture(rig, "hybrid", knock_from=spec.frame_names.index(bit))
        got = detect_motion(knocked, spec, decoded)
        assert got.share > MAX_MOTION_SHARE and {bit, f"{bit}_inv"} <= set(got.moved_frames), got.describe()


def test_a_knock_is_caught_on_the_blocks_of_a_hybrid_without_its_finest_gray_bits():
    """Issue 51: a hybrid without its Gray bits below 2 (``min_bit``: its Gray code names blocks of 4 px, checked as the
    Gray code of its blocks, rangekit.coded.binary.gray_blocks) on the small rig: a 2 mm knock from col_b2, its finest
    column bit, on is refused (14.6%; 26.5% by the blocks' spacing), a still capture is not (0.00%); the frames named
    are all after the move: the column phase frames (rangekit.coded.motion.blocks.frames_after; col_b2 is not named:
    with a 16 px period over 4 px blocks its edges are placed by col_b3's too, which the knock displaced by more than
    a block). Before issue 51 such a capture was not checked."""
    rig = small_projector_rig()
    options = {"steps": 8, "period": 16, "min_bit": 2}
    spec, still = _capture(rig, "hybrid", **options)
    assert "col_b1" not in spec.frame_names
    decoded = np.isfinite(decode(still, spec).proj_col)
    assert detect_motion(still, spec, decoded).share < 0.5 * MAX_MOTION_SHARE
    _, knocked = _capture(rig, "hybrid", knock_from=spec.frame_names.index("col_b2"), mm=2.0, **options)
    got = detect_motion(knocked, spec, decoded)
    assert got.share > 5 * MAX_MOTION_SHARE, got.describe()
    first = spec.frame_names.index("col_b2")
    assert "col_p16_s0" in got.moved_frames, got.describe()
    assert all(spec.frame_names.index(f) >= first for f in got.moved_frames) and got.undersampled == ()


@pytest.mark.slow
def test_a_half_millimetre_knock_with_the_48_frame_hybrid():
    """The default rig and ``hybrid-8step-min3`` (no Gray bits below 3, 8 px blocks; the default pattern set), its
    Gray block edges checked against the phase (rangekit.coded.motion.blocks): a still capture 0.000%, a 0.5 mm
    knock from col_b3 (the finest column bit it projects) on 15.0%, from col_b4 10.5%, from col_p16_s0 (the column
    phase frames: no Gray bit's edges disagree with another's, the 60-frame check sees 0.1%) 16.2% (refused over 2%;
    the check of the blocks' spacing before: 19.3% and 4.9%, the phase frames not seen; the 60-frame hybrid: 3.0%
    from col_b3)."""
    from rangekit.app.scan.presets import PRESETS

    rig = default_rig()
    options = PRESETS["hybrid-8step-min3"].options
    spec, still = _capture(rig, "hybrid", **options)
    decoded = np.isfinite(decode(still, spec).proj_col)
    assert detect_motion(still, spec, decoded).share < 0.001
    for bit, share in (("col_b3", 5 * MAX_MOTION_SHARE), ("col_b4", 1.5 * MAX_MOTION_SHARE),
                       ("col_p16_s0", 5 * MAX_MOTION_SHARE)):
        _, knocked = _capture(rig, "hybrid", knock_from=spec.frame_names.index(bit), **options)
        got = detect_motion(knocked, spec, decoded)
        assert got.share > share, (bit, got.describe())
        # the frames after the move named: from the knocked one on (the column phase frames too), none before it
        first = spec.frame_names.index(bit)
        assert bit in got.moved_frames and "col_p16_s7" in got.moved_frames, (bit, got.describe())
        assert all(spec.frame_names.index(f) >= first for f in got.moved_frames), (bit, got.describe())


@pytest.mark.slow
@pytest.mark.parametrize("obj, still_share, knock, knocked_share", [
    ("bowl", 0.0000, "col_p16_s0", 0.102), ("thin", 0.0000, "col_p16_s0", 0.023),
    ("bunny", 0.0027, "col_p16_s0", 0.292), ("bunny", 0.0027, "col_b5", 0.068)])
def test_the_48_frame_check_on_the_zoo_and_the_upright_bunny(tmp_path, obj, still_share, knock, knocked_share):
    """Issue 51: ``hybrid-8step-min3`` on the zoo's concave and thin objects and the upright Stanford bunny (shared
    data; skipped without it), still and knocked 0.5 mm from ``knock`` on: the still shares measured (the bunny's
    bumps flagged 4.2-9.7% of a view when the blocks' spacing was checked; six 6-view scan views now 0.00-0.27%),
    each knock refused (over 2%: the share of all the decoded pixels, the table's included, so the thin object's
    is small; the 60-frame hybrid's check: 2.0% from col_b3, the phase frames not seen)."""
    from rangekit.app.scan.presets import PRESETS

    if obj == "bunny":            # turned upright as `rangekit scan --up 0 1 0` does
        from support.shared_data import require_shared

        from rangekit.app.scan.setup import _object_bytes

        name, data = _object_bytes(str(require_shared("stanford-bunny", "bun_zipper.ply")), (0.0, 1.0, 0.0))
        (tmp_path / name).write_bytes(data)
        obj = str(tmp_path / name)
    rig = default_rig()
    options = PRESETS["hybrid-8step-min3"].options
    spec, still = _capture(rig, "hybrid", obj=obj, **options)
    decoded = np.isfinite(decode(still, spec).proj_col)
    got = detect_motion(still, spec, decoded)
    assert got.share <= max(2 * still_share, 0.001) < 0.5 * MAX_MOTION_SHARE, got.describe()
    _, knocked = _capture(rig, "hybrid", knock_from=spec.frame_names.index(knock), obj=obj, **options)
    got = detect_motion(knocked, spec, decoded)
    assert got.share > MAX_MOTION_SHARE and got.share > 0.8 * knocked_share, got.describe()


def test_where_the_camera_undersamples_the_projector_nothing_is_checked():
    """The suite's 320x256 camera under the 1280x800 projector: about 4 codes a pixel, where noise turns codes back
    as a move would (5.8% of a still capture flagged): both axes said unchecked, nothing flagged."""
    rig = small_rig()
    spec, still = _capture(rig, "graycode")
    dec = decode(still, spec)
    decoded = np.isfinite(dec.proj_col)
    from rangekit.coded.binary import axis_code
    from rangekit.coded.frames import CaptureStack

    code = axis_code(CaptureStack(still, spec, "rangekit"), spec, "columns", 1, 96)
    assert code_step(code, decoded) >= 3                          # measured 4
    full = check_motion(CaptureStack(still, spec, "rangekit"), spec, {"columns": code}, decoded)
    assert full.undersampled == ("columns",) and full.share == 0.0 and not full.mask.any()
    assert "not checked" in detect_motion(still, spec, decoded).describe()


def test_a_capture_too_fine_for_the_camera_says_not_checked():
    """Issue 48: a capture whose codes the camera does not resolve reported motion=0.0%; it says not checked."""
    from rangekit.coded.decode import decode
    from rangekit.coded.patterns import make_pattern_spec
    from rangekit.sim import SimRig, default_scene
    from support.small_rigs import small_rig

    rig = small_rig()                       # a 320x256 camera under a 1280x800 projector
    spec = make_pattern_spec("graycode", (rig.projector.width, rig.projector.height))
    res = decode(SimRig(default_scene(), rig, seed=1).capture_sequence(list(spec.frames())), spec, motion=True)
    assert res.motion is None and res.motion_unchecked == ("columns", "rows")
    assert "motion=not checked (columns and rows)" in repr(res) and "motion=0" not in repr(res)
