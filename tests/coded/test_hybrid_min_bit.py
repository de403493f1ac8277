"""Hybrid patterns without their finest Gray bits (``min_bit``, issue 51 Deliver 2): the Gray code names 2**m-pixel
blocks, the phase the column inside; against the simulator's truth and against the full code's own decode."""

import numpy as np
import pytest
from scipy.ndimage import binary_erosion

from rangekit.coded.decode import decode
from rangekit.coded.patterns import make_pattern_spec
from rangekit.errors import PatternError
from rangekit.sim import SimRig, default_scene


def test_frames_are_the_full_codes_without_the_finest_bits():
    full = make_pattern_spec("hybrid", (1280, 800))
    short = make_pattern_spec("hybrid", (1280, 800), min_bit=3)
    assert (full.n_frames, short.n_frames) == (60, 48)
    assert short.frame_names == [n for n in full.frame_names if n.split("_")[1:2] not in (["b0"], ["b1"], ["b2"])]
    assert all(np.array_equal(short.frame_by_name(n), full.frame_by_name(n)) for n in short.frame_names[::7])
    assert make_pattern_spec("hybrid", (1280, 800), min_bit=0).frame_names == full.frame_names


@pytest.mark.parametrize("options, text", [({"min_bit": 4}, "blocks of 16 px, more than half the 16 px period"),
                                           ({"min_bit": 2, "period": 6}, "blocks of 4 px"),
                                           ({"min_bit": -1}, "min_bit"), ({"min_bit": 1.5}, "min_bit")])
def test_a_block_wider_than_half_the_period_is_refused(options, text):
    with pytest.raises(PatternError, match=text):
        make_pattern_spec("hybrid", (1280, 800), **options)


def test_the_columns_without_the_finest_bits_are_the_full_codes_columns():
    """The sphere on the default rig: the 48-frame capture is the 60-frame one's frames by name; its columns equal
    the full code's wherever both decode (the same phase, unwrapped to the same period), it decodes the same pixels
    within 0.1%, and away from the rim its columns are within 0.05 projector px RMS of the truth's."""
    sim = SimRig(default_scene("sphere"), seed=1)
    full = make_pattern_spec("hybrid", sim.projector.resolution)
    short = make_pattern_spec("hybrid", sim.projector.resolution, min_bit=3)
    stack = np.stack(sim.capture_sequence(list(full.frames())))
    index = {n: i for i, n in enumerate(full.frame_names)}
    a = decode(stack, full, response=sim.rig.projector_response)
    b = decode(stack[[index[n] for n in short.frame_names]], short, response=sim.rig.projector_response)
    truth = sim.ground_truth()
    both = np.isfinite(a.proj_col) & np.isfinite(b.proj_col)
    assert np.array_equal(a.proj_col[both], b.proj_col[both]) and np.array_equal(a.proj_row[both], b.proj_row[both])
    assert abs(int(np.isfinite(b.proj_col).sum()) - int(np.isfinite(a.proj_col).sum())) <= 1e-3 * both.sum()
    lit = both & binary_erosion(truth.lit & (truth.object_id == 0), iterations=3)   # away from the rim
    assert lit.sum() > 10_000
    assert np.sqrt(np.mean((b.proj_col[lit] - truth.proj_col[lit]) ** 2)) <= 0.05


@pytest.mark.parametrize("size, m", [((1280, 800), 3), ((320, 200), 2), ((1000, 750), 3)])
def test_a_hybrids_gray_frames_are_the_gray_code_of_its_blocks(size, m):
    """rangekit.coded.binary.gray_blocks (issue 51, the motion check of a min_bit code): the hybrid's white, black and
    Gray frames are, frame for frame and pixel for pixel, a graycode capture of its 2**m px blocks, each block frame
    pixel 2**m x 2**m projector pixels (the last block cut at the projector's edge)."""
    from rangekit.coded.binary import gray_blocks
    from rangekit.coded.frames import CaptureStack

    spec = make_pattern_spec("hybrid", size, min_bit=m)
    stack = np.stack(list(spec.frames()))
    fr, blocks = gray_blocks(CaptureStack(stack, spec, "rangekit"), spec)
    assert blocks.method == "graycode" and blocks.n_frames < spec.n_frames
    assert np.shares_memory(fr.stack, stack)
    for i in range(blocks.n_frames):
        big = np.repeat(np.repeat(blocks.frame(i), 1 << m, axis=0), 1 << m, axis=1)[:size[1], :size[0]]
        name = blocks.frame_names[i]
        if name.startswith(("col_b", "row_b")):
            b = int(name[5:].split("_")[0])
            name = f"{name[:5]}{b + m}{name[5 + len(str(b)):]}"
        assert spec.frame_names[i] == name
        np.testing.assert_array_equal(big, stack[i], err_msg=name)
