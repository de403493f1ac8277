"""Photometric stereo speed: 96 images of 612x512 (the DiLiGenT size), and normal integration at 612x512.

Input: an analytic Lambertian + Blinn-Phong sphere filling most of a 612x512 frame (about 177k mask
pixels), 96 lights spread like DiLiGenT's (5-45 deg from the view axis), attached shadows, noise. The
peer is plain least squares with ``numpy.linalg.lstsq`` over the whole mask (what the published L2
baseline does); there is no photometric-stereo routine in OpenCV or Open3D. Median of 3.

Run: .venv/bin/python benchmarks/photometric/bench_photometric.py [--markdown]

``--markdown`` prints the two tables of docs/benchmarks.md (a ``make docs-figures`` block).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from rangekit.photometric import angular_error, integrate_normals, photometric_stereo
from rangekit.sim.sensors.lightstage import light_stage_lights

ROOT = Path(__file__).resolve().parents[2]  # the repo (this is benchmarks/ROOM/SCRIPT.py)
sys.path[:0] = [str(ROOT / "benchmarks" / "harness"), str(ROOT / "tools")]  # _timing, tree_peak; docs_scan
from _timing import timed  # noqa: E402


def scene(H: int = 512, W: int = 612, f: int = 96, seed: int = 0):
    lights = light_stage_lights(f, rng=seed)
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    r = 0.49 * min(H, W) * 1.15
    x, y = (u - W / 2) / r, (v - H / 2) / r
    mask = x * x + y * y < 0.98
    n = np.stack([x, y, -np.sqrt(np.clip(1 - x * x - y * y, 0, None))], axis=-1)
    n[~mask] = np.nan
    N = n[mask]
    shade = np.clip(N @ lights.T, 0, None)                                # (p, f)
    h = lights + np.array([0.0, 0.0, -1.0])
    h /= np.linalg.norm(h, axis=1, keepdims=True)
    spec = 0.5 * np.clip(N @ h.T, 0, None) ** 50 * (shade > 0)
    rng = np.random.default_rng(seed)
    I = 0.8 * shade + spec + rng.normal(0, 0.003, shade.shape)
    images = np.zeros((f, H, W), np.float32)
    images[:, mask] = I.T.astype(np.float32)
    return images, lights, mask, n



def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--markdown", action="store_true", help="print the tables of docs/benchmarks.md")
    md = ap.parse_args().markdown
    images, lights, mask, n_true = scene()
    if not md:
        print(f"96 images of 612x512, {int(mask.sum()):,} mask pixels")

    def numpy_lstsq():
        X = np.linalg.lstsq(lights, images[:, mask].astype(np.float64), rcond=None)[0].T
        out = np.full(mask.shape + (3,), np.nan)
        out[mask] = X / np.linalg.norm(X, axis=1, keepdims=True)
        return out

    rows = []
    t, n = timed(numpy_lstsq)
    rows.append(("numpy lstsq (peer, least squares)", t, angular_error(n, n_true, mask).mean_deg))
    t, res = timed(lambda: photometric_stereo(images, lights, mask, method="ls"))
    rows.append(("rangekit ls", t, angular_error(res.normals, n_true, mask).mean_deg))
    t, res = timed(lambda: photometric_stereo(images, lights, mask, method="robust"))
    rows.append(("rangekit robust", t, angular_error(res.normals, n_true, mask).mean_deg))
    print("| method | time | mean angular error |")
    print("|---|---|---|")
    for name, t, e in rows:
        target = " (target <= 60 s)" if md and name == "rangekit robust" else ""
        print(f"| {name} | {t:.2f} s{target} | {e:.2f} deg |")

    full = np.ones(mask.shape, bool)
    v, u = np.mgrid[0:512, 0:612].astype(np.float64)
    Z = 20 * np.sin(u / 60) * np.cos(v / 45)                              # smooth surface, pixel units
    gz_u, gz_v = np.gradient(Z, axis=1), np.gradient(Z, axis=0)
    n = np.stack([gz_u, gz_v, -np.ones_like(Z)], axis=-1)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    print()
    print("| integration (612x512, full frame) | time | depth RMS / range |")
    print("|---|---|---|")
    label = {"lsq": "sparse least squares (any mask)", "fft": "Frankot-Chellappa (FFT, rectangles)"}
    for method in ("lsq", "fft"):
        t, D = timed(lambda: integrate_normals(n, full, method=method))
        e = (D - D.mean()) - (Z - Z.mean())
        target = " (target <= 2 s)" if md and method == "lsq" else ""
        print(f"| {label[method] if md else method} | {t:.2f} s{target} | {np.sqrt(np.mean(e ** 2)) / np.ptp(Z) * 100:.3f}% |")


if __name__ == "__main__":
    main()
