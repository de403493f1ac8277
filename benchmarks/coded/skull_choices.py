"""The choices made for SLStudio's skull presets (docs/real-captures.md, "SLStudio's skull"), each measured as the
pinned real-data test measures (tests/real_data/test_real_figures.py): the authors' points to the plane of their 8
nearest points of a cloud, and the roughness over every point within 2 mm of the same 4000 of their points.

- Gray code: rangekit's decoded columns against the centres of SLStudio's 2-column blocks (the column convention),
  the projector's distortion kept or left out (the +0.040 mm offset), the per-patch roughness ratio; how far the
  finest stripes' crossings lie off the coarser bits' edges (the reason for ``min_edge_bit`` 1), and the preset's
  decode options each changed in turn (``min_edge_bit``, ``max_gap``, ``stripe_smoothing``, smoothing across the
  stripes too) with issue 47's four figures: within 0.5 mm, median, roughness against the authors', points;
- modulated: the phase presets' ``edge_margin`` 1 (the default) and 0 (kept).

    PYTHONPATH=. .venv/bin/python benchmarks/coded/skull_choices.py     # about two minutes; needs ../shared/data
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def main() -> int:
    import scipy.io

    import rangekit.coded.decode  # noqa: F401  (the module, under the name its function shadows)
    from rangekit.app.commands.reconstruct import reconstruct_tool_capture
    from rangekit.formats.layouts import LAYOUTS, in_projector_pixels
    from rangekit.formats.rig_files.importers import import_rig
    from rangekit.metrology.cloud_compare import distances_to_nearest_planes, local_planes
    from rangekit.rig.rig_file import Rig

    skull = ROOT.parent / "shared" / "data" / "slstudio-skull"
    if not (skull / "calibration" / "calibration.xml").is_file():
        print(f"{skull} is absent: nothing to measure")
        return 0
    ref = scipy.io.loadmat(skull / "skull_gray" / "pointCloud.mat")["xyz"].reshape(-1, 3)
    ref = ref[np.isfinite(ref).all(axis=1)]
    at = ref[np.random.default_rng(0).choice(len(ref), 4000, replace=False)]
    theirs = local_planes(ref, at, 2.0)

    def figures(rec) -> str:
        cloud = np.asarray(rec.cloud.points) * 1000
        d = distances_to_nearest_planes(ref, cloud, k=8, max_radius=1.0, signed=True)
        near = np.abs(d) < 0.5
        ours = local_planes(cloud, at, 2.0)
        both = np.isfinite(ours.rms) & np.isfinite(theirs.rms) & (theirs.rms > 0)
        rough = np.nanmedian(ours.rms)
        return (f"{np.mean(near):.1%} within 0.5 mm, median {np.median(np.where(np.isnan(d), np.inf, np.abs(d))):.4f} "
                f"mm, signed median {np.median(d[near]):+.4f} mm, roughness {rough:.4f} mm = "
                f"{rough / np.nanmedian(theirs.rms):.3f}x theirs ({np.nanmedian(theirs.rms):.4f}; per-patch ratio median "
                f"{np.median(ours.rms[both] / theirs.rms[both]):.2f}), {len(cloud) / len(ref):.2f}x their points")

    def gray_with(rig, **decode_options):
        """The Gray-code preset with ``decode_options`` changed (the preset's own where none are given)."""
        vo = {**gray.view_options, "decode_options": {**gray.view_options["decode_options"], **decode_options}}
        LAYOUTS["slstudio:graycode"] = replace(gray, view_options=vo)
        try:
            return reconstruct_tool_capture([skull / "skull_gray"], "slstudio:graycode", rig).reconstruction
        finally:
            LAYOUTS["slstudio:graycode"] = gray

    calibration = skull / "calibration" / "calibration.xml"
    rigs = {"kp left out (default)": Rig.from_dict(import_rig(calibration)),
            "kp kept": Rig.from_dict(import_rig(calibration, keep_projector_distortion=True))}
    gray = LAYOUTS["slstudio:graycode"]
    for name, rig in rigs.items():
        rec = reconstruct_tool_capture([skull / "skull_gray"], "slstudio:graycode", rig).reconstruction
        print(f"Gray code, {name}: {figures(rec)}")
    cols = in_projector_pixels(rec.decoded, gray, 1824, 1140).proj_col
    whole = reconstruct_tool_capture([skull / "skull_gray"], "slstudio:graycode", rig, subpixel=False).reconstruction
    block_centre = in_projector_pixels(whole.decoded, gray, 1824, 1140).proj_col     # each code at its block's centre
    ok = np.isfinite(cols) & np.isfinite(block_centre)
    print(f"Gray code subpixel columns - their 2-column block's centre: mean {np.mean(cols[ok] - block_centre[ok]):+.4f}"
          f", median {np.median(cols[ok] - block_centre[ok]):+.4f} columns (SLStudio's own column is 2n + (n & 1): "
          "half a column either side of the centre)")

    print(finest_edges_offset(skull / "skull_gray", gray))
    rig = rigs["kp left out (default)"]
    print(f"Gray code, the preset ({gray.view_options['decode_options']}): {figures(gray_with(rig))}")
    for change in ({"min_edge_bit": 0, "max_gap": 6.0, "stripe_smoothing": 2},     # the preset before issue 47's fix
                   {"min_edge_bit": 0}, {"min_edge_bit": 0, "max_gap": 6.0}, {"max_gap": 6.0},
                   {"stripe_smoothing": 0}, {"stripe_smoothing": 2}, {"stripe_smoothing": 4}):
        print(f"Gray code, {change}: {figures(gray_with(rig, **change))}")

    module = sys.modules["rangekit.coded.decode"]
    plain = module.smooth_along_stripes

    def across_too(coord, axis, half, max_step=2.0):
        out = plain(coord, axis, half, max_step)
        return plain(out, "rows" if axis == "columns" else "columns", 1, max_step)

    module.smooth_along_stripes = across_too
    try:
        for change in ({"min_edge_bit": 0, "max_gap": 6.0, "stripe_smoothing": 2}, {}):
            print(f"Gray code, {change or 'the preset'}, smoothed across the stripes too (1 2 1): "
                  f"{figures(gray_with(rig, **change))}")
    finally:
        module.smooth_along_stripes = plain

    modulated = LAYOUTS["slstudio:modulated"]
    for margin in (1, 0):
        LAYOUTS["slstudio:modulated"] = replace(modulated, view_options={**modulated.view_options, "edge_margin": margin})
        try:
            rec = reconstruct_tool_capture([skull / "skull_modulatedps"], "slstudio:modulated",
                                           rigs["kp left out (default)"]).reconstruction
        finally:
            LAYOUTS["slstudio:modulated"] = modulated
        print(f"modulated, edge_margin {margin}: {figures(rec)}")
    return 0


def finest_edges_offset(folder: Path, layout) -> str:
    """How far each bit's stripe edges lie from the midpoint of the two edges beside them along the camera row
    (camera pixels; an edge whose neighbours are one code away on either side): bit 0's edges against the others',
    and theirs against bit 0's. Zero where every bit's stripes cross where they belong; the same sign at rising
    and falling edges is a shift of the finest stripes against the others (not a stripe wider lit than dark)."""
    from rangekit.coded.binary import axis_code, axis_crossings, edge_bit_lut
    from rangekit.coded.frames import CaptureStack
    from rangekit.formats.capture import read_stack
    from rangekit.formats.layouts import arrange, capture_frames

    frames = capture_frames([folder], layout, 1824, 1140, cameras=1)[0]
    stack, spec = arrange(list(read_stack(frames.files, what="skull_gray")), layout, 1824, 1140)
    fr = CaptureStack(stack, spec, "rangekit")
    code = axis_code(fr, spec, "columns", 2, 96)
    t = axis_crossings(fr, spec, "columns", code)
    y, x = np.nonzero(np.isfinite(t))                                  # row-major: along each row in turn
    pos, lo = x + t[y, x], np.minimum(code[y, x], code[y, x + 1])
    mid = np.arange(1, len(y) - 1)
    step = lo[mid] - lo[mid - 1]
    ok = (y[mid - 1] == y[mid + 1]) & (np.abs(step) == 1) & (lo[mid + 1] - lo[mid] == step)
    mid = mid[ok]
    off = pos[mid] - 0.5 * (pos[mid - 1] + pos[mid + 1])
    bit = edge_bit_lut(spec.width)[lo[mid]]
    keep = np.abs(off) < 2
    return (f"Gray code, each stripe edge against the midpoint of its neighbours along the row: bit 0's "
            f"{np.mean(off[keep & (bit == 0)]):+.3f} px, the coarser bits' {np.mean(off[keep & (bit > 0)]):+.3f} px "
            f"(mean over {np.count_nonzero(keep & (bit == 0))} and {np.count_nonzero(keep & (bit > 0))} edges)")


if __name__ == "__main__":
    sys.exit(main())
