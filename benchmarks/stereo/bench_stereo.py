"""Active stereo speed and accuracy: rangekit census + SGM vs OpenCV StereoSGBM on the same rectified pair.

Input: the simulated OAK-D-Pro-like pair (:func:`rangekit.sim.sensors.stereo.stereo_rig`, 640x400, baseline 75 mm)
looking at the textureless box + sphere + wall of :func:`stereo_scene` (0.6-1.1 m) under the random-dot
projector; both images rectified once (:func:`rectify_images`), then each matcher runs on the same input
with 64 disparities. Peer: ``cv2.StereoSGBM`` (MODE_SGBM, 5 paths, block 5, P1 = 200, P2 = 800,
disp12MaxDiff 1, uniquenessRatio 5), the matcher OpenCV users reach for. Ours: 9x7 census, 8 paths,
P1 = 10, P2 = 120, uniqueness 0.05, LR check 1 px, equiangular sub-pixel, 3x3 median.

Accuracy is against the simulator's exact left-camera depth, on the raw left grid
(:func:`depth_in_camera`), over the "matchable" pixels: seen by both cameras, true disparity < 63, at
least 5 px from the border. Times: the minimum wall (and CPU) of 15 alternating runs of the three
matchers, on 1 and on 2 threads (numba.set_num_threads and cv2.setNumThreads); census-SGM must give the
same disparities on both.

Run: .venv/bin/python benchmarks/stereo/bench_stereo.py
     .venv/bin/python benchmarks/stereo/bench_stereo.py --asm      (packed int16 instructions and overlap tests in
     the aggregation of one row, compiled noalias and not)
     .venv/bin/python benchmarks/stereo/bench_stereo.py --parts    (census-SGM's stages timed apart: census of both
     images, sgm_match, the 3x3 median; min of 15 on 1 and 2 threads)
     .venv/bin/python benchmarks/stereo/bench_stereo.py --tables   (docs/stereo.md's accuracy tables, a make
     docs-figures block: 320x200 and 640x400, dots on and off, both matchers through stereo_depth)
     .venv/bin/python benchmarks/stereo/bench_stereo.py --markdown            (docs/benchmarks.md's timing table and
     its targets sentence; with ``--markdown accuracy`` its accuracy table, one run of each matcher, no timing)
"""

from __future__ import annotations

import sys
import time

import cv2
import numba
import numpy as np

from rangekit.sim.sensors.stereo import render_stereo, stereo_rig, stereo_scene
from rangekit.stereo import depth_in_camera, rectify, rectify_images, sgbm_disparity, sgm_disparity, stereo_depth


N_DISP = 64
REPEAT = 15


def min_of_runs(fns, repeat, outs):
    """{name: (min wall s, min CPU s)} over ``repeat`` rounds calling every fn once per round (alternating,
    so that load on a shared machine hits all alike), after one warm-up round; outs[name] = last result."""
    for name, fn in fns.items():
        outs[name] = fn()
    best = {name: [np.inf, np.inf] for name in fns}
    for _ in range(repeat):
        for name, fn in fns.items():
            w, c = time.perf_counter(), time.process_time()
            outs[name] = fn()
            best[name][0] = min(best[name][0], time.perf_counter() - w)
            best[name][1] = min(best[name][1], time.process_time() - c)
    return {name: tuple(v) for name, v in best.items()}


def packed_ops() -> None:
    """Count the packed int16 minimum/add instructions numba emits for one row of the 8-path aggregation
    (rangekit.stereo._sgm._row, compiled afresh: a cached function carries no assembly), compiled
    ``noalias`` as rangekit does and without it; ``setb`` counts the run-time overlap tests LLVM adds when
    it cannot rule out that the row buffers overlap."""
    import re
    from collections import Counter

    from numba.core.compiler import Compiler

    from rangekit._runtime.noalias import NoAliasCompiler
    from rangekit.stereo import _sgm
    W, lanes = 40, 32
    crow, e, o = (np.zeros((W, lanes), np.int16) for _ in range(3))
    Lp, Lc = (np.zeros((3, W + 2, lanes + 2), np.int16) for _ in range(2))
    Mp, Mc = (np.zeros((3, W + 2), np.int16) for _ in range(2))
    h0, h1 = (np.zeros(lanes + 2, np.int16) for _ in range(2))
    for label, pipeline in (("noalias (rangekit)", NoAliasCompiler), ("plain njit", Compiler)):
        row = numba.njit(nogil=True, pipeline_class=pipeline)(_sgm._row.py_func)

        @numba.njit
        def call(crow, Lp, Mp, Lc, Mc, h0, h1, e, o):
            row(crow, Lp, Mp, Lc, Mc, h0, h1, e, o, False, True, np.int16(10), np.int16(120))

        call(crow, Lp, Mp, Lc, Mc, h0, h1, e, o)
        asm = next(iter(row.inspect_asm().values()))
        ops = Counter(re.findall(r"^\s+(vpminsw|vpaddw|vpsubw|vminss|setb)\s", asm, re.M))
        print(f"instructions in _sgm._row, {label}:", dict(ops))
    print("(packed int16: vpminsw / vpaddw / vpsubw; scalar: vminss; setb: run-time overlap tests)")


def parts() -> None:
    """census-SGM's stages on the benchmark pair, each timed alone (min of REPEAT after a warm-up)."""
    from rangekit.stereo import _kernels, _sgm
    from rangekit.stereo.matching import census_transform
    rig = stereo_rig(640, 400)
    cap = render_stereo(stereo_scene(), rig, dots=True, seed=0)
    L, R = (np.asarray(im, np.uint8) for im in rectify_images(rectify(*rig.cameras), cap.left, cap.right))
    cl, cr = census_transform(L, (9, 7)), census_transform(R, (9, 7))
    disp, conf = np.empty(L.shape, np.float32), np.empty(L.shape, np.float32)
    stages = {
        "census, both images": lambda: (census_transform(L, (9, 7)), census_transform(R, (9, 7))),
        "sgm_match (cost, 8 paths, winner-take-all, left-right check)": lambda: _sgm.sgm_match(
            cl, cr, 0, N_DISP, np.int16(62), np.int16(10), np.int16(120), True, 0.05, 2, 1, disp, conf),
        "3x3 median": lambda: _kernels.median3(disp, np.empty_like(disp)),
    }
    n_all = numba.get_num_threads()
    print("| stage | 1 thread | 2 threads |\n|---|---|---|")
    for name, fn in stages.items():
        times = []
        for threads in (1, 2):
            numba.set_num_threads(min(threads, n_all))
            times.append(min_of_runs({name: fn}, REPEAT, {})[name][0])
        print(f"| {name} | {times[0] * 1e3:.1f} ms | {times[1] * 1e3:.1f} ms |")
    numba.set_num_threads(n_all)


def accuracy(dmap, rect, left, cap, mask):
    depth = depth_in_camera(dmap, rect, left)
    ok = mask & np.isfinite(depth)
    e = depth[ok] - cap.depth[ok]
    return ok.sum() / mask.sum(), float(np.sqrt(np.mean(e ** 2))), float(np.median(np.abs(e))), \
        (np.abs(e) < 0.01).sum() / mask.sum(), (np.abs(e) > 0.05).sum() / mask.sum()


def main(markdown: str | None = None) -> None:
    """Timing and accuracy tables; ``markdown``: None (all, with headers), "timing" or "accuracy" (one
    docs/benchmarks.md block each)."""
    rig = stereo_rig(640, 400)
    left, right = rig.cameras
    cap = render_stereo(stereo_scene(), rig, dots=True, seed=0)
    rect = rectify(left, right)
    Lr, Rr = rectify_images(rect, cap.left, cap.right)
    d_true = rect.focal * rect.baseline / cap.depth
    mask = cap.visible & (d_true < N_DISP - 1)
    mask[:5], mask[-5:], mask[:, :5], mask[:, -5:] = False, False, False, False
    if markdown is None:
        print(f"640x400, {N_DISP} disparities, {int(mask.sum()):,} matchable pixels, "
              f"{numba.get_num_threads()} threads available")

    ours = lambda: sgm_disparity(Lr, Rr, num_disparities=N_DISP)  # noqa: E731
    peer = lambda: sgbm_disparity(Lr, Rr, num_disparities=N_DISP, P1=200, P2=800)  # noqa: E731
    peer_hh = lambda: sgbm_disparity(Lr, Rr, num_disparities=N_DISP, P1=200, P2=800, mode="hh")  # noqa: E731
    n_all = numba.get_num_threads()
    rows, outs = [], {}
    if markdown == "accuracy":
        outs = {"ours": ours(), "sgbm": peer(), "hh": peer_hh()}
        print(f"Accuracy is measured against the exact depth on the raw left grid, over the {int(mask.sum()):,} "
              "matchable pixels:\nseen by both cameras, true disparity < 63, and at least 5 px from the border.\n")
    for threads in (1, 2) if markdown != "accuracy" else ():
        numba.set_num_threads(min(threads, n_all))
        cv2.setNumThreads(threads)
        best = min_of_runs({"ours": ours, "sgbm": peer, "hh": peer_hh}, REPEAT, outs)
        rows.append((threads, best))
        if threads == 1:
            d_one = outs["ours"].disparity
        elif not np.array_equal(d_one, outs["ours"].disparity, equal_nan=True):
            raise SystemExit("census-SGM gave different disparities on 1 and 2 threads")
    numba.set_num_threads(n_all)
    cv2.setNumThreads(n_all)
    d_ours, d_peer, d_hh = outs["ours"], outs["sgbm"], outs["hh"]
    if markdown != "accuracy":
        timing_table(rows, markdown == "timing")
    if markdown == "timing":
        return
    if markdown is None:
        print()
    print("| matcher | coverage | RMS depth error | median abs error | within 1 cm | off by > 5 cm |")
    print("|---|---|---|---|---|---|")
    for name, dm in (("rangekit census-SGM", d_ours), ("OpenCV SGBM", d_peer), ("OpenCV SGBM HH", d_hh)):
        cov, rms, med, good, gross = accuracy(dm, rect, left, cap, mask)
        print(f"| {name} | {cov * 100:.1f}% | {rms * 1e3:.1f} mm | {med * 1e3:.2f} mm | {good * 100:.1f}% | "
              f"{gross * 100:.2f}% |")


def timing_table(rows, markdown: bool) -> None:
    """The min-of-runs table per thread count and the speed targets against SGBM."""
    if not markdown:
        print(f"wall: min of {REPEAT} alternating runs after a warm-up (CPU = user + sys of the process, min)")
    print("| threads | rangekit census-SGM (8 paths) | OpenCV SGBM (5 paths) | ratio | OpenCV SGBM HH (8 paths) "
          "| ratio |")
    print("|---|---|---|---|---|---|")
    for threads, b in rows:
        (wo, co), (wp, cp), (wh, ch) = b["ours"], b["sgbm"], b["hh"]
        print(f"| {threads} | {wo * 1e3:.0f} ms ({co * 1e3:.0f} CPU) | {wp * 1e3:.0f} ms ({cp * 1e3:.0f} CPU) | "
              f"{wo / wp:.2f}x | {wh * 1e3:.0f} ms ({ch * 1e3:.0f} CPU) | {wo / wh:.2f}x |")
    one, two = rows[0][1], rows[1][1]
    r1, r2 = one["ours"][0] / one["hh"][0], two["ours"][0] / two["sgbm"][0]
    if markdown:
        print(f"\nTargets: census-SGM on 1 thread <= 1.5x SGBM HH ({r1:.2f}x: {'met' if r1 <= 1.5 else 'MISSED'}), "
              f"on 2 threads <= 1x SGBM ({r2:.2f}x: {'met' if r2 <= 1 else 'MISSED'}); the disparities are the "
              "same on 1 and 2 threads (the benchmark checks it).")
    else:
        print(f"\ntargets: 1 thread census-SGM / SGBM HH = {r1:.2f} (<= 1.5), "
              f"2 threads census-SGM / SGBM = {r2:.2f} (<= 1); same disparities on 1 and 2 threads")


def _length(x: float, mm_below: float) -> str:
    """A depth error in mm under ``mm_below`` metres, else in m."""
    return f"{x * 1e3:.1f} mm" if x < mm_below else f"{x:.{0 if x >= 10 else 2}f} m"


def tables() -> None:
    """docs/stereo.md's tables (a ``make docs-figures`` block): coverage and errors of both matchers with
    and without dots (stereo_depth picks the disparities), at 320x200 and 640x400."""
    for W, H in ((320, 200), (640, 400)):
        rig = stereo_rig(W, H)
        rows = []
        for dots in (True, False):
            cap = render_stereo(stereo_scene(), rig, dots=dots, seed=0)
            for method, label in (("census-sgm", "census-SGM"), ("sgbm", "OpenCV SGBM")):
                res = stereo_depth(cap.left, cap.right, *rig.cameras, method=method)
                rect, n_disp = res.rectification, res.disparity.num_disparities
                mask = cap.visible & (rect.focal * rect.baseline / cap.depth < n_disp - 1)
                mask[:5], mask[-5:], mask[:, :5], mask[:, -5:] = False, False, False, False
                ok = mask & np.isfinite(res.depth)
                e = np.abs(res.depth - cap.depth)[ok]
                occluded = cap.hit & ~cap.visible
                rows.append(f"| {label}, {'dots' if dots else 'no dots'} | {ok.sum() / mask.sum():.1%} | "
                            f"{_length(float(np.sqrt(np.mean(e ** 2))), 1.0)} | {_length(float(np.median(e)), 0.1)} | "
                            f"{(e < 0.01).sum() / mask.sum():.1%} | {np.isnan(res.depth[occluded]).mean():.1%} |")
        if W != 320:
            print()
        print(f"| {W}x{H}, {n_disp} disparities | coverage | RMS | median abs error | within 1 cm | "
              "occluded band invalidated |")
        print("|---|---|---|---|---|---|")
        print("\n".join(rows))


if __name__ == "__main__":
    if "--tables" in sys.argv[1:]:
        tables()
    elif "--parts" in sys.argv[1:]:
        parts()
    elif "--asm" in sys.argv[1:]:
        packed_ops()
    elif "--markdown" in sys.argv[1:]:
        main("accuracy" if "accuracy" in sys.argv[1:] else "timing")
    else:
        main()
