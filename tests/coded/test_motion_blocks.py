"""The check of a hybrid without its finest Gray bits: each Gray block edge against the phase
(rangekit.coded.motion.blocks, issue 51), on the simulator's still capture (the offsets are the noise's, whatever the
surface) and on offsets made by hand (a whole bit's edges moved alike stay a move)."""

from __future__ import annotations

import numpy as np

from rangekit.coded.binary import axis_code, axis_crossings, edge_bit_lut, gray_blocks
from rangekit.coded.frames import CaptureStack
from rangekit.coded.motion.blocks import MAX_BIT_BIAS_SHARE, edge_offsets, offset_baseline, read_edges, wrapped_phase
from rangekit.coded.motion.check import MAX_CODE_STEP, MOTION_LIMIT_CODES, READ_SIGMAS, pair_noise
from rangekit.coded.decode import decode
from rangekit.coded.patterns import make_pattern_spec
from rangekit.sim import SimRig, default_scene
from support.small_rigs import small_projector_rig


def test_a_still_capture_s_block_edges_fall_where_the_phase_says():
    """The small rig (320x256 camera, 320x200 projector), ``min_bit`` 2 (4 px blocks), the default object: each
    column block edge's offset from the phase is the noise's: measured on 2002 edges, median -0.0015 px, 1.4826 MAD
    0.034 px, 0.05% past the 0.3 px limit."""
    rig = small_projector_rig()
    spec = make_pattern_spec("hybrid", (rig.projector.width, rig.projector.height), steps=8, period=16, min_bit=2)
    stack = np.stack(SimRig(default_scene(), rig, seed=5).capture_sequence(list(spec.frames())))
    decoded = np.isfinite(decode(stack, spec).proj_col)
    fr = CaptureStack(stack, spec, "rangekit")
    blocks_fr, blocks = gray_blocks(fr, spec)
    code = axis_code(fr, spec, "columns", 1, 96)
    t = axis_crossings(fr, spec, "columns", code)
    nb = blocks.bits("columns")
    frames = (np.array([blocks_fr.index[f"col_b{b}"] for b in range(nb)]),
              np.array([blocks_fr.index[f"col_b{b}_inv"] for b in range(nb)]))
    weak = READ_SIGMAS * pair_noise(blocks_fr, int(frames[0][-1]), int(frames[1][-1]), decoded, False)
    sure, bit = read_edges(stack, code, t, frames, edge_bit_lut(blocks.width), weak, False)
    u, period = wrapped_phase(fr, spec, "columns")
    off = edge_offsets(code, t, u, period, 4, decoded, sure, MAX_CODE_STEP)
    v = off[np.isfinite(off)]
    assert v.size > 1500
    assert abs(np.median(v)) < 0.02 and 1.4826 * np.median(np.abs(v)) < 0.1
    assert np.mean(np.abs(v) > MOTION_LIMIT_CODES) < 0.01


def test_a_whole_bit_moved_alike_is_not_taken_for_the_projector_s_bias():
    """Offsets made by hand, 40 lines of 100 crossings: noise of 0.03 px; bit 1's edges all moved 1 px (a large object
    moved evenly), bit 2's by 0.05 px (a projector's own bias). Bit 2's bias is taken off; bit 1's is taken off only
    up to half the limit, so its edges stay over it; the limit is the noise's along the stripe, not raised by the
    move (the offsets' own spread would be)."""
    rng = np.random.default_rng(0)
    lines, n = 40, 100
    bit = np.tile(np.arange(n) % 3, (lines, 1))
    off = rng.normal(0.0, 0.03, (lines, n)) + np.where(bit == 1, 1.0, 0.0) + np.where(bit == 2, 0.05, 0.0)
    off[:, ::7] = np.nan
    out, limit = offset_baseline(off, bit, 3, MOTION_LIMIT_CODES, 3.0, line_pairs=False)
    assert limit == MOTION_LIMIT_CODES            # 3 x the noise (0.09 px) is under the limit
    ok = np.isfinite(out)
    assert np.all(np.abs(out[ok & (bit == 1)]) > 1.0 - MAX_BIT_BIAS_SHARE * MOTION_LIMIT_CODES - 0.2)
    assert abs(np.median(out[ok & (bit == 2)])) < 0.01
    assert np.mean(np.abs(out[ok & (bit != 1)]) > limit) < 0.001
