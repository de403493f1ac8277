"""Continuous-wave ToF decoding speed: one 640x480 frame, 16/80/120 MHz x 3 steps (9 raw samples).

There is no ToF decoder in OpenCV or Open3D. The peer is the straightforward implementation: the same
N-bucket phases (numpy arctan2), then unwrapping by brute force over every tuple of wrap counts
(n_16, n_80, n_120) inside the 18.7 m unambiguous range (2 x 10 x 15 = 300 tuples), keeping the tuple
whose ranges agree best. rangekit searches only the 15 wrap counts of the finest frequency and rounds
the others, with inverse-variance weights, and adds the flying-pixel filter, depth and points.

Run: .venv/bin/python benchmarks/tof/bench_tof.py [--markdown]

``--markdown`` prints the table and the ratio of docs/benchmarks.md (a ``make docs-figures`` block).
"""

from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path

import numpy as np

from rangekit.sim.sensors.tof import KINECT_V2_PLAN, render_tof, tof_camera, tof_scene
from rangekit.tof import decode_cw, phase_amplitude_offset

ROOT = Path(__file__).resolve().parents[2]  # the repo (this is benchmarks/ROOM/SCRIPT.py)
sys.path[:0] = [str(ROOT / "benchmarks" / "harness"), str(ROOT / "tools")]  # _timing, tree_peak; docs_scan
from _timing import timed  # noqa: E402



def brute_force(samples, plan):
    phase = phase_amplitude_offset(samples, plan).phase
    U = plan.wrap_lengths
    rho = phase / (2 * np.pi) * U[:, None, None]
    counts = [range(int(np.ceil(plan.unambiguous_range / u - 1e-9))) for u in U]
    best, best_r = np.full(phase.shape[1:], np.inf), np.full(phase.shape[1:], np.nan)
    w = (np.asarray(plan.frequencies) / 1e6) ** 2
    for n in itertools.product(*counts):
        r = rho + np.asarray(n)[:, None, None] * U[:, None, None]
        mean = np.tensordot(w, r, axes=1) / w.sum()
        cost = np.tensordot(w, (r - mean) ** 2, axes=1)
        better = cost < best
        best = np.where(better, cost, best)
        best_r = np.where(better, mean, best_r)
    return best_r


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--markdown", action="store_true", help="print the table of docs/benchmarks.md")
    md = ap.parse_args().markdown
    cam = tof_camera(640, 480)
    cap = render_tof(tof_scene(0.5, 15.0), KINECT_V2_PLAN, camera=cam, seed=1)
    s = cap.sensor
    good = cap.hit & ~cap.mixed
    decode_cw(cap.samples, cap.plan, cam)  # warm the lens cache, as a streaming sensor would
    t_ours, res = timed(lambda: decode_cw(cap.samples, cap.plan, cam, electrons_per_unit=s.electrons_per_dn,
                                          read_noise_e=s.read_noise_e, saturation=65535))
    t_peer, r_peer = timed(lambda: brute_force(cap.samples, cap.plan), repeat=1)

    def correct(r):
        return float((np.abs(r - cap.range_true)[good] < 0.5 * cap.plan.wrap_lengths.min()).mean())

    if not md:
        print(f"640x480, {cap.plan.describe()}, {int(good.sum()):,} unmixed pixels, panels 0.5-15 m\n")
    print("| decoder | time | right wrap count |")
    print("|---|---|---|")
    name = "`decode_cw` (15 candidates" if md else "decode_cw (search 15 wraps"
    print(f"| rangekit {name}, weights, flying filter, depth, points) | {t_ours * 1e3:.0f} ms | "
          f"{correct(res.unwrap.range):.4%} |")
    print(f"| brute force over 300 wrap tuples (numpy) | {t_peer * 1e3:.0f} ms | {correct(r_peer):.4%} |")
    if md:
        print(f"\nRatio: rangekit {t_peer / t_ours:.1f}x faster; {int(good.sum()):,} unmixed pixels.")
    else:
        print(f"\nratio: rangekit is {t_peer / t_ours:.1f}x faster")


if __name__ == "__main__":
    main()
