"""Photometric stereo on the zoo's hard objects (docs/photometric.md): mean angular error of least squares
and of the robust method on ``bowl`` (concave: cast shadows of the rim, one bounce of interreflection)
and ``shiny`` (saturated Blinn-Phong highlights), the default light stage (320 x 256, 96 lights 5-45 deg
from the view axis, 32 bounce rays per pixel, noise), against the renderer's exact normals.

    .venv/bin/python benchmarks/photometric/bench_photometric_zoo.py [--width 320] [--lights 96] [--bounce 32]

Prints one line per object: errors over the mask and more than 3 px inside the silhouette, the
robust / least-squares ratio, the seconds each method takes. The figures are quoted in docs/photometric.md:
``--markdown`` prints its table rows and the robust method's times (a ``make docs-figures`` block).
"""

from __future__ import annotations

import argparse
import time

import cv2
import numpy as np

from rangekit.photometric import angular_error, photometric_stereo
from rangekit.sim.sensors.lightstage import light_stage_camera, light_stage_lights, light_stage_scene, render_light_stage


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--width", type=int, default=320, help="camera width, px (height = 0.8 x width)")
    ap.add_argument("--lights", type=int, default=96)
    ap.add_argument("--bounce", type=int, default=32, help="interreflection rays per pixel (0: none)")
    ap.add_argument("--markdown", action="store_true", help="print docs/photometric.md's table")
    args = ap.parse_args()
    if args.markdown:
        print("| object (default light stage) | least squares | robust | ratio | required |")
        print("|---|---|---|---|---|")
    times = []
    cam = light_stage_camera(args.width, args.width * 4 // 5)
    for obj in ("bowl", "shiny"):
        cap = render_light_stage(light_stage_scene(obj), light_stage_lights(args.lights, rng=0), camera=cam,
                                 bounce_samples=args.bounce)
        inner = cap.mask & (cv2.distanceTransform(cap.mask.astype(np.uint8), cv2.DIST_L2, 3) > 3)
        row = {}
        for method in ("ls", "robust"):
            t = time.perf_counter()
            n = photometric_stereo(cap.images, cap.lights, cap.mask, method=method).normals
            row[method] = (angular_error(n, cap.normals_true, cap.mask).mean_deg,
                           angular_error(n, cap.normals_true, inner).mean_deg, time.perf_counter() - t)
        (ls, ls_in, t_ls), (rob, rob_in, t_rob) = row["ls"], row["robust"]
        if args.markdown:
            print(f"| {obj} ({int(cap.mask.sum()):,} px) | {ls:.2f} deg | {rob:.2f} deg | {rob / ls:.2f} | <= 0.6 |")
            times.append(f"{t_rob:.2f} s on {obj}")
            continue
        print(f"{obj:6s} {int(cap.mask.sum())} px: least squares {ls:.2f} deg (inner {ls_in:.2f}), robust {rob:.2f} "
              f"deg (inner {rob_in:.2f}), ratio {rob / ls:.3f} (inner {rob_in / ls_in:.3f}); "
              f"{t_ls:.2f} s / {t_rob:.2f} s")
    if args.markdown:
        print(f"\nThe robust method takes {' and '.join(times)} (least squares: a fraction of a second).")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
