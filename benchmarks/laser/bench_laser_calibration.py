"""Laser-plane calibration on the simulator's rendered board frames (the acceptance criterion of
laser-line scanning: from 10 board poses, each plane's normal within 0.02 deg and offset within 0.02 mm of the truth).

`rangekit.app.laser.calibration.calibrate_lasers` on the default laser rig (two lasers at +-30 deg), 10 board
poses, seeds 0-4, three ways of getting the board poses from the detected corners: PnP with the camera's
intrinsics (the laser calibration alone), the same with the board texture rendered at full resolution, and
the default: the camera calibrated (Zhang) from the same images plus 10 camera poses, placed at the true
camera pose, whose principal point error turns the planes (see docs/laser.md). Prints per seed the worst
normal angle error (deg) and offset error (mm) over the lasers, and the wall time.

Run: .venv/bin/python benchmarks/laser/bench_laser_calibration.py [--markdown]

``--markdown`` prints docs/laser.md's table rows (worst over the seeds, median time; a ``make docs-figures``
block).
"""

from __future__ import annotations

import statistics
import sys
import time

from rangekit.app.laser.calibration import calibrate_lasers
from rangekit.sim.laser.rig import laser_rig


def main() -> None:
    rig = laser_rig()
    calibrate_lasers(rig, n_poses=2, camera=rig.camera)  # warm up (open3d, numba, ray caches)
    md = "--markdown" in sys.argv[1:]
    rows = {"camera intrinsics, PnP (texture at 1/2 resolution)":
            "the camera's intrinsics + PnP, 10 poses, texture at half resolution (`ambient_scale=2`, the default)",
            "camera intrinsics, PnP (texture at full resolution)": "the same, texture at full resolution",
            "camera calibrated from the images (default)":
            "a camera calibrated (Zhang) from these 10 images plus 10 camera poses, at the true pose"}
    if md:
        print("| board poses from | normal angle, offset (worst over the lasers and seeds 0-4) | time per "
              "calibration (median) |\n|---|---|---|")
    for label, kw in (("camera intrinsics, PnP (texture at 1/2 resolution)", dict(camera=rig.camera)),
                      ("camera intrinsics, PnP (texture at full resolution)", dict(camera=rig.camera, ambient_scale=1)),
                      ("camera calibrated from the images (default)", {})):
        worst, times = [0.0, 0.0], []
        for seed in range(5):
            t = time.perf_counter()
            res = calibrate_lasers(rig, n_poses=10, seed=seed, **kw)
            dt = time.perf_counter() - t
            deg, mm = res.worst()
            worst, times = [max(worst[0], deg), max(worst[1], mm)], times + [dt]
            if not md:
                print(f"{label}: seed {seed}: {deg:.5f} deg, {mm:.5f} mm, {dt:.1f} s, rejected {len(res.rejected)}")
        if md:
            print(f"| {rows[label]} | {worst[0]:.4f} deg, {worst[1]:.4f} mm | {statistics.median(times):.1f} s |")
        else:
            print(f"WORST {label}: {worst[0]:.5f} deg, {worst[1]:.5f} mm")


if __name__ == "__main__":
    main()
