"""One camera with a random-dot projector (rangekit.stereo.dots_depth) against two-camera active stereo
(rangekit.stereo.stereo_depth) on the same simulated scene (the box, sphere and wall of stereo_scene) at the same
resolution and baseline (75 mm): coverage of the visible pixels (5 px from the border), depth RMS and median error
against the truth, and the time of each call (median of 5, alternating, one process; the images already in memory).

    PYTHONPATH=. .venv/bin/python benchmarks/stereo/bench_dots.py [320x200 640x400]
"""

from __future__ import annotations

import statistics
import sys
import time

import numpy as np

from rangekit.sim.sensors.dots import dots_rig, render_dots
from rangekit.sim.sensors.stereo import render_stereo, stereo_rig, stereo_scene
from rangekit.stereo import dots_depth, stereo_depth


def _stats(depth, truth, visible):
    mask = np.zeros_like(visible)
    mask[5:-5, 5:-5] = visible[5:-5, 5:-5]
    ok = mask & np.isfinite(depth)
    e = depth[ok] - truth[ok]
    return f"coverage {ok.sum() / mask.sum():.1%}, RMS {np.sqrt(np.mean(e ** 2)) * 1e3:.1f} mm, " \
           f"median {np.median(np.abs(e)) * 1e3:.1f} mm"


def main(sizes) -> None:
    for size in sizes:
        W, H = (int(v) for v in size.split("x"))
        rig, pair = dots_rig(W, H), stereo_rig(W, H)
        dcap, scap = render_dots(stereo_scene(), rig, seed=0), render_stereo(stereo_scene(), pair, seed=0)
        cam = rig.cameras[0]

        def one():
            return dots_depth(dcap.image, dcap.reference, cam, rig.projector, dcap.reference_distance)

        def two():
            return stereo_depth(scap.left, scap.right, *pair.cameras)

        one(), two()            # numba's compiled kernels loaded
        times = {"one": [], "two": []}
        for _ in range(5):
            for name, call in (("one", one), ("two", two)):
                t = time.perf_counter()
                call()
                times[name].append(time.perf_counter() - t)
        print(f"{W}x{H}: one camera + dots: {_stats(one().depth, dcap.depth, dcap.visible)}, "
              f"{statistics.median(times['one']) * 1e3:.0f} ms")
        print(f"{W}x{H}: two cameras:       {_stats(two().depth, scap.depth, scap.visible)}, "
              f"{statistics.median(times['two']) * 1e3:.0f} ms")


if __name__ == "__main__":
    main(sys.argv[1:] or ["320x200", "640x400"])
