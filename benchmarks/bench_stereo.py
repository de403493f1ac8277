"""Active stereo speed and accuracy: rangekit census + SGM vs OpenCV StereoSGBM on the same rectified pair.

Input: the simulated OAK-D-Pro-like pair (:func:`rangekit.sim.stereo.stereo_rig`, 640x400, baseline 75 mm)
looking at the textureless box + sphere + wall of :func:`stereo_scene` (0.6-1.1 m) under the random-dot
projector; both images rectified once (:func:`rectify_images`), then each matcher runs on the same input
with 64 disparities. Peer: ``cv2.StereoSGBM`` (MODE_SGBM, 5 paths, block 5, P1 = 200, P2 = 800,
disp12MaxDiff 1, uniquenessRatio 5), the matcher OpenCV users reach for. Ours: 9x7 census, 8 paths,
P1 = 10, P2 = 120, uniqueness 0.05, LR check 1 px, equiangular sub-pixel, 3x3 median.

Accuracy is against the simulator's exact left-camera depth, on the raw left grid
(:func:`depth_in_camera`), over the "matchable" pixels: seen by both cameras, true disparity < 63, at
least 5 px from the border. Median of 5 runs, on 1 thread and on all threads.

Run: .venv/bin/python benchmarks/bench_stereo.py
     .venv/bin/python benchmarks/bench_stereo.py --tables   (docs/stereo.md's accuracy tables: 320x200 and
     640x400, dots on and off, both matchers through stereo_depth)
"""

from __future__ import annotations

import sys

import cv2
import numba
import numpy as np

from rangekit.sim.stereo import render_stereo, stereo_rig, stereo_scene
from rangekit.stereo import depth_in_camera, rectify, rectify_images, sgbm_disparity, sgm_disparity, stereo_depth

from _timing import timed  # benchmarks/_timing.py (the script's folder is on sys.path)

N_DISP = 64



def accuracy(dmap, rect, left, cap, mask):
    depth = depth_in_camera(dmap, rect, left)
    ok = mask & np.isfinite(depth)
    e = depth[ok] - cap.depth[ok]
    return ok.sum() / mask.sum(), float(np.sqrt(np.mean(e ** 2))), float(np.median(np.abs(e))), \
        (np.abs(e) < 0.01).sum() / mask.sum(), (np.abs(e) > 0.05).sum() / mask.sum()


def main() -> None:
    rig = stereo_rig(640, 400)
    left, right = rig.cameras
    cap = render_stereo(stereo_scene(), rig, dots=True, seed=0)
    rect = rectify(left, right)
    Lr, Rr = rectify_images(rect, cap.left, cap.right)
    d_true = rect.focal * rect.baseline / cap.depth
    mask = cap.visible & (d_true < N_DISP - 1)
    mask[:5], mask[-5:], mask[:, :5], mask[:, -5:] = False, False, False, False
    print(f"640x400, {N_DISP} disparities, {int(mask.sum()):,} matchable pixels, "
          f"{numba.get_num_threads()} threads available")

    ours = lambda: sgm_disparity(Lr, Rr, num_disparities=N_DISP)  # noqa: E731
    peer = lambda: sgbm_disparity(Lr, Rr, num_disparities=N_DISP, P1=200, P2=800)  # noqa: E731
    peer_hh = lambda: sgbm_disparity(Lr, Rr, num_disparities=N_DISP, P1=200, P2=800, mode="hh")  # noqa: E731
    rows = []
    n_all = numba.get_num_threads()
    for threads in (1, n_all):
        numba.set_num_threads(threads)
        cv2.setNumThreads(threads)
        t_ours, d_ours = timed(ours, 5, warmup=1)
        t_peer, d_peer = timed(peer, 5, warmup=1)
        t_hh, d_hh = timed(peer_hh, 5, warmup=1)
        rows.append((threads, t_ours, t_peer, t_hh))
    numba.set_num_threads(n_all)
    cv2.setNumThreads(n_all)

    print("| threads | rangekit census-SGM (8 paths) | OpenCV SGBM (5 paths) | ratio | OpenCV SGBM HH (8 paths) "
          "| ratio |")
    print("|---|---|---|---|---|---|")
    for threads, t_ours, t_peer, t_hh in rows:
        print(f"| {threads} | {t_ours * 1e3:.0f} ms | {t_peer * 1e3:.0f} ms | {t_ours / t_peer:.1f}x slower | "
              f"{t_hh * 1e3:.0f} ms | {t_ours / t_hh:.1f}x slower |")
    print()
    print("| matcher | coverage | RMS depth error | median abs error | within 1 cm | off by > 5 cm |")
    print("|---|---|---|---|---|---|")
    for name, dm in (("rangekit census-SGM", d_ours), ("OpenCV SGBM", d_peer), ("OpenCV SGBM HH", d_hh)):
        cov, rms, med, good, gross = accuracy(dm, rect, left, cap, mask)
        print(f"| {name} | {cov * 100:.1f}% | {rms * 1e3:.1f} mm | {med * 1e3:.2f} mm | {good * 100:.1f}% | "
              f"{gross * 100:.2f}% |")


def tables() -> None:
    """Coverage and errors of both matchers with and without dots (stereo_depth picks the disparities)."""
    for W, H in ((320, 200), (640, 400)):
        rig = stereo_rig(W, H)
        print(f"\n| {W}x{H} | coverage | RMS | median abs error | within 1 cm | occluded band invalidated |")
        print("|---|---|---|---|---|---|")
        for dots in (True, False):
            cap = render_stereo(stereo_scene(), rig, dots=dots, seed=0)
            for method in ("census-sgm", "sgbm"):
                res = stereo_depth(cap.left, cap.right, *rig.cameras, method=method)
                rect, n_disp = res.rectification, res.disparity.num_disparities
                mask = cap.visible & (rect.focal * rect.baseline / cap.depth < n_disp - 1)
                mask[:5], mask[-5:], mask[:, :5], mask[:, -5:] = False, False, False, False
                ok = mask & np.isfinite(res.depth)
                e = np.abs(res.depth - cap.depth)[ok]
                occluded = cap.hit & ~cap.visible
                print(f"| {method}, {'dots' if dots else 'no dots'} ({n_disp} disparities) | "
                      f"{ok.sum() / mask.sum():.1%} | {np.sqrt(np.mean(e ** 2)) * 1e3:.1f} mm | {np.median(e) * 1e3:.1f} mm | "
                      f"{(e < 0.01).sum() / mask.sum():.1%} | {np.isnan(res.depth[occluded]).mean():.1%} |")


if __name__ == "__main__":
    tables() if "--tables" in sys.argv[1:] else main()
