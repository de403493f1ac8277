"""When the interreflection correction applies (rangekit.photometric.cavity_light, docs/photometric.md):
for the simulator's concave objects (bowl: a spherical cavity; bunny, steps, thin: cast shadows lit by
nearby walls, as on real objects), rendered with one bounce of interreflection, and the DiLiGenT ball from
../shared/data: the three criteria, the decision, and the robust method's mean angular error with the
correction forced off and forced on, against the truth.

    .venv/bin/python benchmarks/photometric/bench_cavity_light.py [--width 160] [--lights 48] [--bounce 16]
"""

from __future__ import annotations

import argparse

import numpy as np

from rangekit.photometric import angular_error
from rangekit.photometric.solve import grey_images, solve_chunks, stack_pixels, to_maps
from rangekit.sim.sensors.lightstage import light_stage_camera, light_stage_lights, light_stage_scene, render_light_stage


def _row(name: str, B: np.ndarray, S: np.ndarray, mask: np.ndarray, truth: np.ndarray) -> str:
    B = np.asarray(B, dtype=np.float64)
    G, found = solve_chunks(B, S, "robust", global_rounds=1)
    error = {force: angular_error(to_maps(solve_chunks(B, S, "robust", force_cavity=force)[0], mask)[0], truth,
                                  mask).mean_deg for force in (False, True)}
    off = angular_error(to_maps(solve_chunks(B, S, "robust", global_rounds=0)[0], mask)[0], truth, mask).mean_deg
    return (f"| {name} | {found.lights} | {found.spread:.2f} | {found.misfit:.3f} | {found.coverage:.2f} | "
            f"{'applied' if found.applied else 'not applied'} | {error[False]:.2f} deg | {off:.2f} deg | "
            f"{error[True]:.2f} deg |")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--width", type=int, default=160)
    ap.add_argument("--lights", type=int, default=48)
    ap.add_argument("--bounce", type=int, default=16)
    args = ap.parse_args()
    print("| object | lights measured | spread (<= 0.5) | misfit (<= 0.1) | coverage (>= 0.3) | decision | "
          "robust (as decided) | correction off | correction forced on (before issue 34) |")
    print("|---|---|---|---|---|---|---|---|---|")
    cam = light_stage_camera(args.width, args.width * 4 // 5)
    lights = light_stage_lights(args.lights, rng=0)
    for obj in ("bowl", "bunny", "steps", "thin"):
        cap = render_light_stage(light_stage_scene(obj), lights, camera=cam, bounce_samples=args.bounce)
        print(_row(obj, cap.images[:, cap.mask].T, cap.lights.T, cap.mask, cap.normals_true), flush=True)
    from rangekit.photometric.diligent import load_diligent
    from rangekit.sim.scene.zoo import data_folders

    ball = next((f / "diligent-ball" for f in data_folders() if (f / "diligent-ball" / "filenames.txt").is_file()), None)
    if ball is None:
        print("| DiLiGenT ball | skipped: not in ../shared/data (set RANGEKIT_DATA) | | | | | | | |")
    else:
        d = load_diligent(ball)
        print(_row("DiLiGenT ball", stack_pixels(grey_images(d.images), d.mask), d.lights.T, d.mask, d.normals_gt))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
