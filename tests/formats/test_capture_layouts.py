"""Capture layouts (rangekit.formats.layouts): another tool's frames, in its order and without the
references it never records, decode through rangekit to the exact projector columns; on SLStudio's real
skull capture the cloud agrees with the authors' own (issue 35)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from support.cli_runs import assert_error
from rangekit.coded.decode import decode
from rangekit.errors import FileFormatError
from rangekit.formats.layouts import LAYOUTS, arrange, decoding_projector, layout_files


def _slstudio_2x3_frames(width: int, height: int) -> list[np.ndarray]:
    """SLStudio's six 2x3 frames as its encoder makes them (pstools::computePhaseVector), 8-bit."""
    x = np.arange(width, dtype=np.float64)
    frames = []
    for pitch in (width / 16, width):
        for k in range(3):
            row = 0.5 * (1 + np.cos(2 * np.pi * x / pitch - 2 * np.pi * k / 3))
            frames.append(np.tile(np.round(255 * row).astype(np.uint8), (height, 1)))
    return frames


def _slstudio_gray_frames(width: int, height: int) -> list[np.ndarray]:
    """SLStudio's Gray-code frames as its encoder makes them (EncoderGrayCode): white, black, then bit
    ``ceil(log2(width)) - p`` (1-based) of ``gray(column)`` for p = 0..9."""
    n_bits = int(np.ceil(np.log2(width)))
    gray = np.arange(width) ^ (np.arange(width) >> 1)
    frames = [np.full((height, width), 255, np.uint8), np.zeros((height, width), np.uint8)]
    for p in range(10):
        bit = (gray >> (n_bits - p - 1)) & 1
        frames.append(np.tile((255 * bit).astype(np.uint8), (height, 1)))
    return frames


def test_slstudio_gray_code_as_projected_decodes_to_its_columns():
    """Ten bits of an 11-bit code, no inverses: the blocks of two columns are decoded, and the projector model
    of those blocks puts every camera pixel (here the projector's own pixel) back on its column."""
    layout = LAYOUTS["slstudio:graycode"]
    width, height = 1100, 16                                   # 11 bits: blocks of 2 columns
    stack, spec = arrange(_slstudio_gray_frames(width, height), layout, width, height)
    assert (spec.width, spec.bits("columns"), spec.axes) == (550, 10, ("columns",)) and stack.shape[0] == 22
    dec = decode(stack, spec, **layout.view_options["decode_options"])
    cols = 2 * dec.proj_col[:, 4:-4] + 0.5                     # block c spans columns 2c, 2c + 1
    assert np.isfinite(cols).all()
    assert np.abs(cols - np.arange(width)[4:-4]).max() < 1e-4


def test_the_binned_projector_sees_the_same_rays():
    """A point seen at projector column u is seen by the model of blocks of s columns at (u - (s - 1) / 2) / s,
    at the same row: the binning is exact, not a resampling."""
    from rangekit.camera import PinholeCamera

    K = np.array([[2600.0, 0, 901.3], [0, 2580.0, 1130.2], [0, 0, 1]])
    proj = PinholeCamera(K, 1824, 1140, np.array([-0.05, 0.01, 0.001, -0.002, 0.0]))
    binned = decoding_projector(proj, LAYOUTS["slstudio:graycode"])
    assert binned.size == (912, 1140)
    pts = np.random.default_rng(1).uniform([-0.1, -0.1, 0.4], [0.1, 0.1, 0.6], (200, 3))
    uv, uv_b = proj.project(pts), binned.project(pts)
    np.testing.assert_allclose(uv_b[:, 0], (uv[:, 0] - 0.5) / 2, atol=1e-9)
    np.testing.assert_allclose(uv_b[:, 1], uv[:, 1], atol=1e-9)


def test_made_inverses_follow_the_nearer_reference_rule():
    """A bit is 1 where the frame is nearer white than black: the made inverse is white + black - frame, kept
    in the frames' range (uint8 here, where white + black exceeds it)."""
    frames = _slstudio_gray_frames(1100, 4)
    frames[0] = np.full_like(frames[0], 200)                    # white 200, black 90: the threshold is 145
    frames[1] = np.full_like(frames[1], 90)
    frames[2] = np.tile(np.array([150, 140], np.uint8), (4, 550))
    stack, spec = arrange(frames, LAYOUTS["slstudio:graycode"], 1100, 4)
    frame, inverse = stack[spec.frame_names.index("col_b9")], stack[spec.frame_names.index("col_b9_inv")]
    assert inverse.dtype == np.uint8
    assert (inverse[0, :2] == [140, 150]).all()                 # 290 - 150, 290 - 140
    assert ((frame.astype(int) - inverse > 0) == (frame > 145)).all()


def test_smoothing_along_stripes_keeps_a_slope_and_quiets_noise():
    from rangekit.coded.binary import smooth_along_stripes

    rng = np.random.default_rng(0)
    y, x = np.mgrid[0:200, 0:100]
    slope = (0.37 * y + 1.7 * x).astype(np.float32)
    smooth = smooth_along_stripes(slope, "columns", 2)
    np.testing.assert_allclose(smooth[2:-2], slope[2:-2], atol=1e-4)           # binomial taps keep a line
    assert (smooth[:2] == slope[:2]).all() and (smooth[-2:] == slope[-2:]).all()  # taps outside: unchanged
    noise = rng.normal(0, 0.2, (400, 400)).astype(np.float32)           # 0.2 codes, as on SLStudio's skull
    ratio = smooth_along_stripes(noise, "columns", 2)[2:-2].var() / noise[2:-2].var()
    assert abs(ratio - 70 / 256) < 0.02                          # sum of the squared taps 1 4 6 4 1 / 16
    holed = noise.copy()
    holed[100, 50] = np.nan
    out = smooth_along_stripes(holed, "rows", 1)
    assert np.isnan(out[100, 50]) and out[100, 49] == holed[100, 49] and out[100, 48] != holed[100, 48]
    edge = slope.copy()
    edge[100:] += 40                                             # a depth edge: two surfaces' stripes
    out = smooth_along_stripes(edge, "columns", 2)
    assert (out[98:102] == edge[98:102]).all()                   # taps across the edge: kept as they are
    np.testing.assert_allclose(out[90:97], edge[90:97], atol=1e-4)  # beside it, smoothed (a line stays a line)


def test_slstudio_2x3_as_projected_decodes_to_its_columns():
    """The camera sees the projector pixel for pixel: every column decodes to itself within 8-bit rounding."""
    stack, spec = arrange(_slstudio_2x3_frames(256, 32), LAYOUTS["slstudio:2x3"], 256, 32)
    assert spec.frame_names[:2] == ["white", "black"] and stack.shape == (8, 32, 256)
    dec = decode(stack, spec)
    cols = dec.proj_col[:, 8:-8]                   # the border columns' neighbourhoods are cut by the image edge
    assert np.isfinite(cols).all()
    assert np.abs(cols - np.arange(256)[8:-8]).max() < 0.05


def test_a_missing_or_extra_frame_is_named(tmp_path):
    with pytest.raises(FileFormatError, match="frameSeq_00.bmp ... frameSeq_05.bmp"):
        layout_files(tmp_path, LAYOUTS["slstudio:2x3"], 64, 8)
    with pytest.raises(FileFormatError, match="expected 6 frames for a 64x8 projector, found 5"):
        arrange(_slstudio_2x3_frames(64, 8)[:5], LAYOUTS["slstudio:2x3"], 64, 8)


@pytest.mark.parametrize("suffix, depth, colour", [(".bmp", 8, False), (".tif", 16, False), (".png", 8, True),
                                                     (".png", 16, True), (".jpg", 8, False)])
def test_frames_in_any_format_decode(tmp_path, suffix, depth, colour):
    """SLStudio's 2x3 frames saved as BMP, 16-bit TIFF, colour PNG (8 and 16 bit) or JPEG decode to the
    same columns: a folder converted to another format keeps its names' stems."""
    from rangekit.formats.capture import read_stack

    layout = LAYOUTS["slstudio:2x3"]
    for k, frame in enumerate(_slstudio_2x3_frames(256, 32)):
        image = frame.astype(np.uint16) * 257 if depth == 16 else frame
        image = np.repeat(image[..., None], 3, axis=2) if colour else image
        params = [cv2.IMWRITE_JPEG_QUALITY, 100] if suffix == ".jpg" else []
        assert cv2.imwrite(str(tmp_path / f"frameSeq_{k:02d}{suffix}"), image, params)
    images = read_stack(layout_files(tmp_path, layout, 256, 32))
    assert images.dtype == (np.uint16 if depth == 16 else np.uint8) and images.ndim == (4 if colour else 3)
    stack, spec = arrange(list(images), layout, 256, 32)
    cols = decode(stack, spec).proj_col[:, 8:-8]
    assert np.isfinite(cols).all() and np.abs(cols - np.arange(256)[8:-8]).max() < (0.6 if suffix == ".jpg" else 0.05)


def test_a_folder_with_other_frames_than_the_layout_is_one_line(cli, tmp_path):
    """More frames than the layout has for the rig's projector, frames of two sizes, frames of two depths:
    each named in one line, and no cloud."""
    from rangekit.rig.rig_file import Rig, save_rig
    from rangekit.sim import default_rig

    from rangekit.camera import PinholeCamera

    r = default_rig()
    square = lambda d, w, h: PinholeCamera(np.array([[w, 0, (w - 1) / 2], [0, w, (h - 1) / 2], [0, 0, 1.0]]), w, h,
                                           d.dist, d.T_world_cam, d.name)   # a lens, not a squashed resize
    save_rig(Rig(cameras=(square(r.camera, 64, 8),), projector=square(r.projector, 256, 32)), tmp_path / "rig.json")
    capture = tmp_path / "capture"
    capture.mkdir()
    for k, frame in enumerate(_slstudio_2x3_frames(64, 8) + _slstudio_2x3_frames(64, 8)[:1]):
        cv2.imwrite(str(capture / f"frameSeq_{k:02d}.png"), frame)
    args = ("reconstruct", capture, "--pattern", "slstudio:2x3", "--rig", tmp_path / "rig.json", "--out",
            tmp_path / "c.ply")
    assert_error(cli(*args), 1, "found more (frameSeq_06.png): is the projector size right?")
    (capture / "frameSeq_06.png").unlink()
    cv2.imwrite(str(capture / "frameSeq_03.png"), np.zeros((9, 64), np.uint8))
    assert_error(cli(*args), 1, "frameSeq_03.png", "64x9")
    cv2.imwrite(str(capture / "frameSeq_03.png"), np.zeros((8, 64), np.uint16))
    assert_error(cli(*args), 1, "frameSeq_03.png", "16-bit")
    assert not (tmp_path / "c.ply").exists()


def test_a_layout_without_its_rig_or_its_frames_is_one_line(cli, tmp_path):
    run = cli("reconstruct", tmp_path, "--pattern", "slstudio:2x3", "--out", tmp_path / "c.ply")
    assert_error(run, 2, "--pattern slstudio:2x3", "--rig RIG.json")
    (tmp_path / "rig.json").write_text("{}")
    run = cli("reconstruct", tmp_path, "--pattern", "slstudio:2x3", "--rig", tmp_path / "rig.json",
              "--out", tmp_path / "c.ply")
    assert run.code in (1, 2) and "Traceback" not in run.err and not (tmp_path / "c.ply").exists()


def test_decode_reads_a_tool_folder_into_its_projector_pixels(cli, tmp_path):
    """``rangekit decode DIR --pattern slstudio:graycode --projector WxH``: the maps are in the tool's projector
    pixels (SLStudio's blocks of two columns at their centres), not in the code's blocks."""
    for k, frame in enumerate(_slstudio_gray_frames(1100, 16)):
        cv2.imwrite(str(tmp_path / f"frameSeq_{k:02d}.bmp"), frame)
    run = cli("decode", tmp_path, "--pattern", "slstudio:graycode", "--projector", "1100x16", "--out",
              tmp_path / "maps.npz")
    assert run.code == 0, run.err
    cols = np.load(tmp_path / "maps.npz")["proj_col"][:, 4:-4]
    assert np.isfinite(cols).all() and np.abs(cols - np.arange(1100)[4:-4]).max() < 1e-4
    run = cli("decode", tmp_path, "--pattern", "slstudio:graycode", "--out", tmp_path / "m.npz")
    assert_error(run, 2, "--projector WxH")
