"""The choices made for SLStudio's skull presets (docs/real-captures.md, "SLStudio's skull"), each measured as the
pinned real-data test measures (tests/real_data/test_real_figures.py): the authors' points to the plane of their 8
nearest points of a cloud, and the roughness over every point within 2 mm of the same 4000 of their points.

- Gray code: rangekit's decoded columns against the centres of SLStudio's 2-column blocks (the column convention),
  the projector's distortion kept or left out (the +0.040 mm offset), the per-patch roughness ratio, and smoothing
  across the stripes too (kept off: it moves the median);
- modulated: the phase presets' ``edge_margin`` 1 (the default) and 0 (kept).

    PYTHONPATH=. .venv/bin/python benchmarks/coded/skull_choices.py     # about a minute; needs ../shared/data
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
        return (f"{np.mean(near):.1%} within 0.5 mm, median {np.median(np.where(np.isnan(d), np.inf, np.abs(d))):.4f} "
                f"mm, signed median {np.median(d[near]):+.4f} mm, roughness {np.nanmedian(ours.rms):.4f} mm (theirs "
                f"{np.nanmedian(theirs.rms):.4f}; per-patch ratio median {np.median(ours.rms[both] / theirs.rms[both]):.2f})")

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

    module = sys.modules["rangekit.coded.decode"]
    plain = module.smooth_along_stripes

    def across_too(coord, axis, half, max_step=2.0):
        out = plain(coord, axis, half, max_step)
        return plain(out, "rows" if axis == "columns" else "columns", 1, max_step)

    module.smooth_along_stripes = across_too
    try:
        rec = reconstruct_tool_capture([skull / "skull_gray"], "slstudio:graycode",
                                      rigs["kp left out (default)"]).reconstruction
        print(f"Gray code, smoothed across the stripes too (1 2 1): {figures(rec)}")
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


if __name__ == "__main__":
    sys.exit(main())
