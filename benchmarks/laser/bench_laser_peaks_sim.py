"""Laser-line peak accuracy on the simulator's own frames (the acceptance criterion of laser-line
scanning: RMS column error of the peak <= 0.05 px for the Gaussian or ridge method, line width 0.8 mm,
8-bit camera, default noise; the confidence ranks the errors).

Frames: the default laser rig (`rangekit.sim.laser.rig.laser_rig`), RGB 8-bit, default ImagingModel and
LaserLook, objects lumpy, sphere and (when ../shared/data or ../../shared/data holds it) the Stanford
bunny standing upright (y up in the file), at turntable angles 0, 40, 100 and 200 degrees, both lasers.
Truth: the lit curve's exact image projection (`LitCurve.uv`, distorted pixels), compared by
`rangekit.sim.laser.truth.column_errors` (the curve's column at the peak's row; rows near a curve end or
gap, or where the curve runs along the row, are not compared). Also run with speckle off, and with
speckle, shot and read noise off, to show where the error comes from. Per method: RMS column error,
mean, peaks compared / found, the share of points within 1 px of the curve, and the share of the errors
over 3x the RMS (and of the top-decile errors) that the worst decile by confidence holds.

Run: .venv/bin/python benchmarks/laser/bench_laser_peaks_sim.py [--quick]   (--quick: lumpy and sphere only)

The output is markdown: docs/benchmarks.md quotes it whole (a ``make docs-figures`` block, no
``--markdown`` flag needed).
"""

from __future__ import annotations

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

from rangekit.laser import detect_peaks
from rangekit.sim import default_scene
from rangekit.sim.laser.frames import LaserLook, LaserView
from rangekit.sim.laser.rig import laser_rig
from rangekit.sim.laser.truth import column_errors, curve_distance
from rangekit.sim.scene.objects import load_scene_object
from rangekit.sim.imaging.render import ImagingModel

#: label -> (method, options)
METHODS = {"gaussian": ("gaussian", {}), "gaussian, along=3": ("gaussian", {"along": 3}), "com": ("com", {}),
           "ridge": ("ridge", {})}
_ROOT = Path(__file__).resolve().parents[2]  # the repo (this is benchmarks/laser/bench_laser_peaks_sim.py)
#: the data folder beside the checkout (ROOT/../shared), or beside the worktrees' folder (ROOT/../../shared)
BUNNY = next((p for p in (_ROOT.parent / "shared", _ROOT.parent.parent / "shared")
              if (p / "data" / "stanford-bunny" / "bun_zipper.ply").is_file()), _ROOT.parent / "shared") \
    / "data" / "stanford-bunny" / "bun_zipper.ply"


def objects(quick: bool) -> dict:
    out = {"lumpy": default_scene("lumpy"), "sphere": default_scene("sphere")}
    if not quick and BUNNY.is_file():
        bunny = load_scene_object(BUNNY, name="bunny")
        v = bunny.vertices @ np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])   # y up -> z up
        out["bunny"] = default_scene(replace(bunny, vertices=v))
    return out


def measure(scenes: dict, imaging: ImagingModel, look: LaserLook) -> dict:
    rig = laser_rig()
    acc = {m: {"e": [], "c": [], "d": [], "n": 0} for m in METHODS}
    for scene in scenes.values():
        for angle in (0, 40, 100, 200):
            view = LaserView(scene, rig, np.radians(angle), imaging=imaging, look=look, seed=angle, ambient_scale=4)
            off = view.off()
            for k in range(len(rig.lasers)):
                frame = view.frame(k)
                for m, (method, options) in METHODS.items():
                    peaks = detect_peaks(frame.image, off, method=method, channel="red" if imaging.colour else None,
                                         **options)
                    e = column_errors(peaks.points, frame.curve.uv)
                    ok = np.isfinite(e)
                    a = acc[m]
                    a["n"] += len(e)
                    a["e"].append(e[ok])
                    a["c"].append(peaks.confidence[ok])
                    a["d"].append(curve_distance(peaks.points, frame.curve.uv))
    out = {}
    for m, a in acc.items():
        e, c, d = (np.concatenate(a[k]) for k in "ecd")
        rms = float(np.sqrt(np.mean(e ** 2)))
        low = c <= np.quantile(c, 0.1)
        large, top = np.abs(e) > 3 * rms, np.abs(e) >= np.quantile(np.abs(e), 0.9)
        out[m] = dict(rms=rms, mean=float(e.mean()), compared=len(e), found=a["n"], within1=float((d < 1).mean()),
                      large=float((large & low).sum() / max(large.sum(), 1)), top=float((top & low).sum() / top.sum()))
    return out


def main() -> None:
    scenes = objects("--quick" in sys.argv)
    base = ImagingModel(colour=True)
    cases = [("default noise and speckle", base, LaserLook()),
             ("no speckle", base, LaserLook(speckle=0.0)),
             ("no speckle, no shot or read noise", replace(base, full_well=0.0, read_noise=0.0),
              LaserLook(speckle=0.0))]
    print(f"objects: {', '.join(scenes)}; angles 0, 40, 100, 200 deg; both lasers\n")
    print("| frames | method | RMS px | mean px | compared / peaks | within 1 px | worst conf. decile holds: "
          "errors > 3 RMS / top-decile errors |")
    print("|---|---|---|---|---|---|---|")
    for name, imaging, look in cases:
        for m, r in measure(scenes, imaging, look).items():
            print(f"| {name} | {m} | {r['rms']:.3f} | {r['mean']:+.4f} | {r['compared']} / {r['found']} | "
                  f"{100 * r['within1']:.1f}% | {100 * r['large']:.0f}% / {100 * r['top']:.0f}% |")


if __name__ == "__main__":
    main()
