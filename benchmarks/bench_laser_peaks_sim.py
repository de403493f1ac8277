"""Laser-line peak accuracy on the simulator's own frames (issue 17's acceptance: RMS column error of the
peak <= 0.05 px for the Gaussian or ridge method, line width 0.8 mm, 8-bit camera, default noise).

Frames: the default laser rig (`rangekit.sim.laser_rig.laser_rig`), RGB 8-bit, default ImagingModel and
LaserLook, objects lumpy and sphere at turntable angles 0, 40, 100 and 200 degrees, both lasers. Truth: the
lit curve's exact image projection (`LitCurve.uv`, distorted pixels). Each peak (u, v) is compared with the
curve's u interpolated at v from the samples within 0.6 rows and 3 px of the peak (rows where the curve
runs nearly along the row, spreading more than 3 px, are left out). Also run with speckle off, and with
speckle, shot and read noise off, to show where the error comes from.

Run: .venv/bin/python benchmarks/bench_laser_peaks_sim.py
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from rangekit.laser import detect_peaks
from rangekit.sim import default_scene
from rangekit.sim.laser import LaserLook, LaserView
from rangekit.sim.laser_rig import laser_rig
from rangekit.sim.laser_truth import column_errors
from rangekit.sim.render import ImagingModel

METHODS = ("gaussian", "com", "ridge")


def measure(imaging: ImagingModel, look: LaserLook) -> dict[str, tuple[float, int, int]]:
    rig = laser_rig()
    errs = {m: [] for m in METHODS}
    counts = {m: 0 for m in METHODS}
    for obj in ("lumpy", "sphere"):
        for angle in (0, 40, 100, 200):
            view = LaserView(default_scene(obj), rig, np.radians(angle), imaging=imaging, look=look, seed=angle,
                             ambient_scale=4)
            off = view.off()
            for k in range(len(rig.lasers)):
                frame = view.frame(k)
                for m in METHODS:
                    peaks = detect_peaks(frame.image, off, method=m, channel="red" if imaging.colour else None)
                    e = column_errors(peaks.points, frame.curve.uv)
                    counts[m] += len(e)
                    errs[m].append(e[np.isfinite(e)])
    out = {}
    for m in METHODS:
        e = np.concatenate(errs[m])
        out[m] = (float(np.sqrt(np.mean(e ** 2))), len(e), counts[m])
    return out


def main() -> None:
    base = ImagingModel(colour=True)
    cases = [("default noise and speckle", base, LaserLook()),
             ("no speckle", base, LaserLook(speckle=0.0)),
             ("no speckle, no shot or read noise", replace(base, full_well=0.0, read_noise=0.0), LaserLook(speckle=0.0))]
    print("| frames | " + " | ".join(f"{m} RMS px (compared / peaks)" for m in METHODS) + " |")
    print("|---|" + "---|" * len(METHODS))
    for name, imaging, look in cases:
        res = measure(imaging, look)
        print(f"| {name} | " + " | ".join(f"{r:.3f} ({n} / {c})" for r, n, c in res.values()) + " |")


if __name__ == "__main__":
    main()
