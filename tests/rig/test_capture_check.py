"""The rig checked against its own capture (rangekit.rig.capture_check, issue 47 item 1) on the simulator: the true
rig predicts the decoded projector coordinates to the decoding noise, a rig whose projector is off by a known
amount is caught by about that amount, and a capture of columns alone says it cannot be checked."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from rangekit.geometry import make_T
from rangekit.rig.capture_check import POOR_FIT_PX, check_rig


def _turned(projector, degrees: float, axis: str = "x"):
    """The projector turned by ``degrees`` about its own x axis (its rows move by about f * angle, across the
    epipolar lines of a camera beside it) or y axis (its columns move: along the epipolar lines, mostly a change
    of depth that the capture cannot tell from the surface's shape)."""
    a = np.radians(degrees)
    c, s = np.cos(a), np.sin(a)
    R = (np.array([[1, 0, 0], [0, c, -s], [0, s, c]]) if axis == "x" else np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]))
    return replace(projector, T_world_cam=projector.T_world_cam @ make_T(R, np.zeros(3)))


def test_the_true_rig_fits_to_the_decoding_noise(decoded_graycode):
    rig, dec = decoded_graycode
    check = check_rig(rig.camera, rig.projector, dec.proj_col, dec.proj_row)
    assert check.checkable and check.fits
    assert check.median_px < 0.1, check           # measured 0.012 px, 0.016 mm (turned 0.5 deg: 3.24 px of 3.27)
    assert check.median_mm < 0.2, check
    assert "fits the capture" in check.describe()


def test_a_projector_turned_by_half_a_degree_is_caught_by_about_what_it_moves(decoded_graycode):
    rig, dec = decoded_graycode
    expected_px = rig.projector.K[1, 1] * np.radians(0.5)      # its rows move by f * angle
    check = check_rig(rig.camera, _turned(rig.projector, 0.5, "x"), dec.proj_col, dec.proj_row)
    assert not check.fits and check.median_px > POOR_FIT_PX
    assert 0.7 * expected_px < check.median_px < 1.3 * expected_px, (check, expected_px)
    assert "does NOT fit" in check.describe()
    # Along the epipolar lines a misfit is mostly a change of depth: a turn about y is seen only in part.
    along = check_rig(rig.camera, _turned(rig.projector, 0.5, "y"), dec.proj_col, dec.proj_row)
    assert along.median_px < 0.5 * check.median_px


def test_columns_alone_cannot_check_the_rig(decoded_graycode):
    rig, dec = decoded_graycode
    check = check_rig(rig.camera, _turned(rig.projector, 5.0, "x"), dec.proj_col, None)
    assert not check.checkable and "none possible" in check.describe()


def test_a_projector_size_the_capture_cannot_have_is_refused_naming_it(decoded_graycode):
    """A capture made for the rig's projector decoded with a pattern set of a narrower one of as many bits (issue
    47): the lit pixels past the narrower width are named, with the size they need; the capture's own size decodes
    no pixel past its projector."""
    from rangekit.coded.decode import decode
    from rangekit.coded.patterns import make_pattern_spec
    from rangekit.errors import DecodeError
    from rangekit.sim import SimRig, default_scene

    rig, _ = decoded_graycode
    rig = replace(rig, projector=rig.projector.resized(400, 200))   # the camera sees its columns 70-330
    W, H = rig.projector.width, rig.projector.height
    spec = make_pattern_spec("graycode", (W, H))
    images = SimRig(default_scene(), rig, seed=1).capture_sequence(list(spec.frames()))
    narrow_w = (1 << (spec.bits("columns") - 1)) + 1                # the narrowest of as many bits
    narrow = make_pattern_spec("graycode", (narrow_w, H))
    assert narrow.bits("columns") == spec.bits("columns") and narrow.n_frames == spec.n_frames
    with pytest.raises(DecodeError) as caught:
        decode(images, narrow)
    message = str(caught.value)
    assert f"{narrow_w}x{H} projector" in message and f"(projector columns {narrow_w}-" in message
    top = int(message.split("at least ")[1].split(" ")[0])
    assert 300 < top < W, message
