"""Simulator speed: render a 44-frame Gray-code sequence at 1280x1024 on the default rig.

Target (the simulator's speed target): at most 3 s for the sequence on a 2-core machine. Side by side with
the naive way a simulator is usually written, ray casting the scene again for every pattern (Open3D RaycastingScene,
same float64 refinement and image model), to show what casting once per view buys.

    .venv/bin/python benchmarks/sim/bench_render.py [--repeat 3] [--naive-frames 44] [--markdown]

Prints a table and exits non-zero if the target is missed; ``--markdown`` prints docs/benchmarks.md's
table instead (a ``make docs-figures`` block, which says whether the target was met and exits 0).
"""

from __future__ import annotations

import argparse
import os
import platform
import sys
import time

import numpy as np

TARGET_S = 3.0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=3, help="timed repetitions (median reported)")
    ap.add_argument("--naive-frames", type=int, default=44, help="frames for the naive re-casting peer")
    ap.add_argument("--markdown", action="store_true", help="print docs/benchmarks.md's table (exit 0)")
    args = ap.parse_args()

    t0 = time.perf_counter()
    import open3d  # noqa: F401  (import cost reported separately)

    from rangekit.coded.patterns import make_pattern_spec
    from rangekit.sim import SimRig, cast_view, default_scene
    from rangekit.sim.imaging.render import ViewRenderer

    t_import = time.perf_counter() - t0
    sim = SimRig(default_scene("lumpy"), seed=0)
    cam, proj = sim.rig.camera, sim.rig.projector
    spec = make_pattern_spec("graycode", proj.size)
    patterns = list(spec.frames())
    assert len(patterns) == 44 and (cam.width, cam.height) == (1280, 1024)

    t = time.perf_counter()
    rays = cam.rays(cam.pixel_grid())
    t_rays = time.perf_counter() - t
    mesh = sim.scene.world_mesh()

    casts, renders, totals = [], [], []
    for rep in range(args.repeat):
        t = time.perf_counter()
        geom = cast_view(mesh, cam, proj, cam_rays=rays)
        renderer = ViewRenderer(geom, sim.imaging, proj.size)
        t_cast = time.perf_counter() - t
        rngs = [np.random.default_rng(i) for i in range(len(patterns))]
        t = time.perf_counter()
        images = renderer.render_many(patterns, rngs, workers=2)
        t_render = time.perf_counter() - t
        casts.append(t_cast)
        renders.append(t_render)
        totals.append(t_cast + t_render)
    assert len(images) == 44 and images[0].shape == (1024, 1280)

    # Peer: cast the scene again for every pattern (what a per-frame ray tracer does).
    n = max(1, min(args.naive_frames, len(patterns)))
    t = time.perf_counter()
    for i in range(n):
        g = cast_view(mesh, cam, proj, cam_rays=rays)
        ViewRenderer(g, sim.imaging, proj.size).render(patterns[i], np.random.default_rng(i))
    t_naive = (time.perf_counter() - t) * len(patterns) / n

    med = float(np.median(totals))
    ok = med <= TARGET_S
    if args.markdown:
        render = float(np.median(renders))
        print("| stage | time | note |\n|---|---|---|")
        print(f"| import open3d + rangekit | {t_import:.2f} s | once per process |")
        print(f"| camera rays, 1.3 M pixels, exact undistortion | {t_rays:.2f} s | once per rig |")
        print(f"| ray cast + shadow rays + float64 refinement | {np.median(casts):.2f} s | once per view |")
        print(f"| render 44 frames (2 threads) | {render:.2f} s | {render / 44 * 1e3:.1f} ms per frame |")
        print(f"| **sequence (cast + render)** | **{med:.2f} s** | target <= {TARGET_S:.0f} s: "
              f"{'met' if ok else 'not met'} ({med + t_rays:.1f} s with the camera rays) |")
        print(f"| peer: ray cast again for every frame | {t_naive:.1f} s | {t_naive / med:.1f}x slower |")
        return 0
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"python {platform.python_version()}")
    print(f"scene: lumpy on turntable, {len(mesh.triangles)} triangles; camera 1280x1024; projector "
          f"{proj.width}x{proj.height}; 44 Gray-code frames, 8-bit, default imaging model")
    print(f"import open3d+rangekit         {t_import:7.3f} s (once per process)")
    print(f"camera rays (1.3 M pixels)     {t_rays:7.3f} s (once per rig)")
    print(f"ray cast + shadow rays (view)  {np.median(casts):7.3f} s (once per view)")
    print(f"render 44 frames (2 threads)   {np.median(renders):7.3f} s ({np.median(renders) / 44 * 1e3:.1f} ms/frame)")
    print(f"sequence total (cast+render)   {med:7.3f} s   target <= {TARGET_S:.1f} s")
    print(f"peer: re-cast every frame      {t_naive:7.3f} s   ({t_naive / med:.1f}x slower; {n} frames timed)")
    print("PASS" if ok else "FAIL: sequence slower than the target")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
