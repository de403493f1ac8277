"""Laser-line peak detection on one 1280x960 8-bit frame: time per frame and RMS error against the known
centres, for a plain per-row argmax, centre of mass, the Gaussian fit and the ridge detector.

Frames from tests/support/laser_lines.py: a pixel-integrated Gaussian profile at a known subpixel column per row
(a smooth curve with every subpixel phase), 200 DN high, 1/e^2 widths 3, 5, 8 px, Gaussian noise of
1 and 2 DN in both the laser-on and the laser-off frame, rounded to 8 bits. The ridge detector's error
is the distance to the curve along its normal; the row methods' the column error per row. A second
frame holds a line at 45 degrees for the ridge detector (the row methods refuse most of its rows).

Run: .venv/bin/python benchmarks/laser/bench_laser_peaks.py

The output is markdown: docs/benchmarks.md quotes it whole (a ``make docs-figures`` block, no
``--markdown`` flag needed).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from rangekit.laser.peaks import detect_peaks

ROOT = Path(__file__).resolve().parents[2]  # the repo (this is benchmarks/ROOM/SCRIPT.py)
sys.path[:0] = [str(ROOT / "benchmarks" / "harness"), str(ROOT / "tools")]  # _timing, tree_peak; docs_scan
sys.path.insert(0, str(ROOT / "tests"))
from _timing import timed  # noqa: E402
from support.laser_lines import curve_line, row_line, slanted  # noqa: E402

H, W = 960, 1280
V = np.arange(H)
CENTRES = 640.0 + 250.0 * np.sin(V / 200.0) + 0.0137 * V
METHODS = ("argmax", "com", "gaussian", "ridge")
LABEL = {"argmax": "per-row argmax (integer column)", "com": "centre of mass, 9 px window",
         "gaussian": "Gaussian fit (weighted log-parabola, >= 5 samples)",
         "ridge": "ridge (Steger on ln S, sigma 1.5 px)"}


def errors(p) -> np.ndarray:
    if p.rows is not None:
        return p.points[:, 0] - CENTRES[p.rows]
    c = np.interp(p.points[:, 1], V, CENTRES)
    slope = np.interp(p.points[:, 1], V, np.gradient(CENTRES))
    return (p.points[:, 0] - c) / np.sqrt(1.0 + slope ** 2)


def main() -> None:
    on, off = row_line(CENTRES, 5.0, 200.0, W=W, noise=1.5, seed=1)
    print(f"{W}x{H} uint8, one line, width 5 px, noise 1.5 DN; median of 20 calls after 3 warm-up calls\n")
    print("| method | time per frame | peaks | RMS error |")
    print("|---|---|---|---|")
    for m in METHODS:
        t, p = timed(lambda: detect_peaks(on, off, method=m), repeat=20, warmup=3)
        print(f"| {LABEL[m]} | {t * 1e3:.1f} ms | {len(p)} | {np.sqrt(np.mean(errors(p) ** 2)):.4f} px |")

    print("\nRMS error (px) by 1/e^2 width and noise (200 DN peak):\n")
    cases = [(w, s) for w in (3.0, 5.0, 8.0) for s in (1.0, 2.0)]
    print("| method | " + " | ".join(f"w {w:.0f}, noise {s:.0f}" for w, s in cases) + " |")
    print("|---|" + "---|" * len(cases))
    frames = {c: row_line(CENTRES, c[0], 200.0, W=W, noise=c[1], seed=int(10 * c[0] + c[1])) for c in cases}
    for m in METHODS:
        rms = []
        for c in cases:
            e = errors(detect_peaks(*frames[c], method=m))
            rms.append(f"{np.sqrt(np.mean(e ** 2)):.4f}")
        print(f"| {LABEL[m]} | " + " | ".join(rms) + " |")

    dist = slanted(45.0, 640.3, 480.0)
    on45, off45 = curve_line(dist, H, W, 5.0, 200.0, noise=1.5, seed=2, ss=4)
    t, p = timed(lambda: detect_peaks(on45, off45, method="ridge"), repeat=5, warmup=1)
    e = dist(p.points[:, 0], p.points[:, 1])
    g = detect_peaks(on45, off45, method="gaussian")
    eg = dist(g.points[:, 0], g.points[:, 1])
    print(f"\nline at 45 degrees, width 5 px, noise 1.5 DN (distances along the normal): ridge {len(p)} points, "
          f"RMS {np.sqrt(np.mean(e ** 2)):.4f} px, {t * 1e3:.1f} ms; Gaussian fit {len(g)} rows, "
          f"RMS {np.sqrt(np.mean(eg ** 2)):.4f} px")


if __name__ == "__main__":
    main()
