"""Every codec rangekit decodes, compared on the simulator's default object (docs/real-captures.md, "Codecs
compared on the simulator").

    PYTHONPATH=. python benchmarks/coded/bench_codecs.py [--markdown] [--repeat 3] [--seed 1] [--object lumpy]

One view of the default simulated rig (1280x1024 camera, 1280x800 projector, the default imaging model: 8 bit,
noise, projector gamma 2.2, blur) of the object's default scene, captured with each codec's frames (columns
only, as the tools' codecs code them), reconstructed by :func:`rangekit.coded.reconstruct.reconstruct_view`
(decode with the rig's projector response, ray-plane triangulation, edge filter: what ``rangekit reconstruct``
does). Per codec:

- frames: captures per view;
- decoded: the share of the object's visible pixels (the camera sees the object there, lit or not) that
  decode to a column, and the median distance (mm) of their ray-plane points from the exact surface point
  of the pixel (the simulator's ground-truth ``xyz``; a median, as the mixed pixels at the silhouette, which
  the filters below drop, would rule an RMS);
- points: the share of those visible pixels with a point after ``reconstruct_view``'s filters (confidence
  3%, flying pixels: a range step over 0.4% to a neighbour, one more pixel around), the points' RMS (mm)
  and the share of points more than 1 mm off;
- decode CPU s/MP: :func:`rangekit.coded.decode.decode` alone, CPU seconds of the process (every thread)
  per megapixel of the camera, median of ``--repeat`` runs after one untimed (numba's compile and cache).

SLStudio's single-period 3-step codec has two rows: as rangekit decodes it by default, and with its column map
blurred as SLStudio blurs it (``decode(..., coord_smoothing=3)``, what the ``slstudio:3ps`` layout passes;
the other rows' filters as they are, not that layout's).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from rangekit.coded.decode import decode
from rangekit.coded.patterns import PatternSpec
from rangekit.coded.reconstruct import reconstruct_view
from rangekit.coded.triangulate import triangulate_ray_plane
from rangekit.sim import SimRig, default_scene


#: The single-period 3-step codec decoded as SLStudio decodes it: the column map blurred (sigma 3 camera pixels,
#: ``CodecPhaseShift3.cpp``), as the ``slstudio:3ps`` capture layout does (``coord_smoothing``).
SMOOTHED_3PS = "SLStudio single period, 3 steps, column blurred as SLStudio does (`coord_smoothing=3`)"
DECODE_OPTIONS = {SMOOTHED_3PS: {"coord_smoothing": 3.0}}


def codecs(width: int, height: int) -> dict[str, PatternSpec]:
    """Codec name -> spec on a ``width`` x ``height`` projector, columns only."""
    W = width
    cols = ("columns",)
    return {
        "`graycode`, subpixel edges (reference)": PatternSpec("graycode", W, height, cols),
        "`phase` default: periods W, W/8, W/64 (reference)": PatternSpec("phase", W, height, cols),
        "`hybrid` default: Gray code + 8 steps of 16 px (reference)": PatternSpec("hybrid", W, height, cols),
        "SLStudio 2x3 (`phase`, periods W, W/16, 3 + 3 steps)": PatternSpec(
            "phase", W, height, cols, {"periods": [W, W / 16], "steps": 3, "fine_steps": 3, "rounding": "down"}),
        "SLStudio single period, 3 steps (`phase`, period W)": PatternSpec(
            "phase", W, height, cols, {"periods": [W], "fine_steps": 3, "rounding": "down"}),
        SMOOTHED_3PS: PatternSpec("phase", W, height, cols, {"periods": [W], "fine_steps": 3, "rounding": "down"}),
        "`micro` (SLStudio's 10 periods, 70-80 px)": PatternSpec("micro", W, height, cols),
        "`modulated` (SLStudio: 24 periods x 16 carrier periods + cue)": PatternSpec("modulated", W, height, cols),
        "`ftp` (OpenCV, 20 periods, + 3-frame cue)": PatternSpec("ftp", W, height, cols),
        "`psp` (OpenCV, 20 periods, + 3-frame cue)": PatternSpec("psp", W, height, cols),
        "`faps` (OpenCV, 20 periods, + 3-frame cue)": PatternSpec("faps", W, height, cols),
    }


def measure(sim: SimRig, spec: PatternSpec, repeat: int, options: dict | None = None) -> dict:
    """One codec's row: frames, decoded share and median error, points' share, RMS and share > 1 mm, decode CPU seconds
    per megapixel; ``options``: more keyword arguments of ``decode``."""
    rig = sim.rig
    options = options or {}
    stack = np.stack(sim.capture_sequence(list(spec.frames())))
    truth = sim.ground_truth()
    dec = decode(stack, spec, response=rig.projector_response, **options)     # also compiles / loads numba's cache
    cpu = []
    for _ in range(repeat):
        t = time.process_time()
        decode(stack, spec, response=rig.projector_response, **options)
        cpu.append(time.process_time() - t)
    rec = reconstruct_view(stack, spec, rig.camera, rig.projector, response=rig.projector_response,
                           decode_options=options)
    visible = truth.hit & (truth.object_id == 0)
    raw = triangulate_ray_plane(rig.camera, rig.projector, dec.proj_col)
    decoded = raw.valid & visible
    err_raw = np.linalg.norm(raw.xyz[decoded] - truth.xyz[decoded], axis=1)
    point = rec.triangulated.valid & visible
    err = np.linalg.norm(rec.triangulated.xyz[point] - truth.xyz[point], axis=1)
    mp = stack.shape[1] * stack.shape[2] / 1e6
    rms = lambda e: float(np.sqrt(np.mean(e ** 2)) * 1e3) if e.size else float("nan")  # noqa: E731
    return {"frames": spec.n_frames, "decoded": decoded.sum() / visible.sum(),
            "median_decoded_mm": float(np.median(err_raw) * 1e3),
            "coverage": point.sum() / visible.sum(), "rms_mm": rms(err),
            "over_1mm": float(np.mean(err > 1e-3)) if err.size else float("nan"),
            "cpu_per_mp": float(np.median(cpu)) / mp}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--object", default="lumpy", help="a built-in object (default: the simulator's default)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--repeat", type=int, default=3, help="timed decodes per codec (median)")
    ap.add_argument("--markdown", action="store_true", help="print docs/real-captures.md's table")
    args = ap.parse_args()
    sim = SimRig(default_scene(args.object), seed=args.seed)
    rows = {}
    for name, spec in codecs(*sim.rig.projector.size).items():
        rows[name] = measure(sim, spec, args.repeat, DECODE_OPTIONS.get(name))
        if not args.markdown:
            r = rows[name]
            print(f"{name}: {r['frames']} frames, decoded {r['decoded']:.1%} (median {r['median_decoded_mm']:.3f} mm), "
                  f"points {r['coverage']:.1%}, RMS {r['rms_mm']:.3f} mm, {r['over_1mm']:.2%} > 1 mm, decode "
                  f"{r['cpu_per_mp']:.2f} CPU-s/MP", flush=True)
    if args.markdown:
        cam = sim.rig.camera
        print(f"Object `{args.object}`, one view, camera {cam.width}x{cam.height}, seed {args.seed}; decode CPU time "
              f"median of {args.repeat}.\n")
        print("| codec | frames | decoded | median decoded (mm) | coverage (points) | RMS points (mm) | points > 1 mm "
              "| decode (CPU s/MP) |")
        print("|---|---|---|---|---|---|---|---|")
        for name, r in rows.items():
            cover = f"{r['coverage']:.1%}" if r["coverage"] >= 0.01 else f"{r['coverage']:.2%}"
            print(f"| {name} | {r['frames']} | {r['decoded']:.1%} | {r['median_decoded_mm']:.3f} | {cover} | "
                  f"{r['rms_mm']:.3f} | {r['over_1mm']:.2%} | {r['cpu_per_mp']:.2f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
