"""The time the devices take to acquire a scan, free-running against triggered by the projector (issue 50
Deliver 3, issue 51 Deliver 1): ``rangekit scan --realtime``'s devices (the projector's 50 ms latency, the turntable
at 30 deg/s settling 0.5 s, the hardware defaults of the rig file: 0.1 s pattern delay, 30 fps, 33 ms exposure) on
the simulator's virtual clock, so the figure is the devices' time whatever the machine's load (the wall time of
``--realtime`` adds rendering when the machine cannot render the frames as fast as the devices take them).

    PYTHONPATH=. python benchmarks/app/bench_triggered.py [--views 12] [--patterns hybrid] [--exposure-us 33333]

Prints, for each mode, the devices' seconds for the scan and per view, and whether the frames are the same bytes.
The camera is the default rig's at 320x256 (its size changes no wait).
"""

from __future__ import annotations

import argparse
import tempfile
from dataclasses import replace
from pathlib import Path

from rangekit.app.acquire.acquire import acquire
from rangekit.coded.patterns import make_pattern_spec
from rangekit.formats.sessions.session import CaptureSettings, ScanPlan
from rangekit.rig.camera_controls import CameraControls
from rangekit.sim import SimRig, default_rig, default_scene
from rangekit.sim.devices.realtime import REALTIME_LATENCY_S, REALTIME_TURNTABLE_DEG_S


def _frames(folder: Path) -> dict:
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.glob("view_*/0*"))}


def run(views: int, patterns: str, exposure_us: float) -> None:
    base = default_rig()
    camera = CameraControls(exposure_us=exposure_us).to_dict()
    spec = make_pattern_spec(patterns, (base.projector.width, base.projector.height))
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        for mode in ("free", "triggered"):
            rig = replace(base, cameras=(base.camera.resized(320, 256),),
                          capture={**base.capture, "camera": camera, **({"trigger": "projector"}
                                                                         if mode == "triggered" else {})})
            sim = SimRig(default_scene("lumpy"), rig, latency_s=REALTIME_LATENCY_S,
                         turntable_speed_deg_s=REALTIME_TURNTABLE_DEG_S)
            capture = CaptureSettings.from_rig(rig, hardware=True)
            acquire(sim, rig, spec, Path(tmp) / mode, plan=ScanPlan(n_views=views), capture=capture)
            out[mode] = (sim.clock.now(), _frames(Path(tmp) / mode))
            print(f"{mode:9s}: {views} views x {spec.n_frames} frames, pattern delay {capture.pattern_delay_s:g} s: "
                  f"devices {out[mode][0]:.2f} s ({out[mode][0] / views:.2f} s a view)")
    free, trig = out["free"], out["triggered"]
    print(f"triggered / free: {trig[0] / free[0]:.2f}x; frames the same bytes: {free[1] == trig[1]}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--views", type=int, default=12)
    parser.add_argument("--patterns", default="hybrid")
    parser.add_argument("--exposure-us", type=float, default=33_333.0)
    args = parser.parse_args()
    run(args.views, args.patterns, args.exposure_us)


if __name__ == "__main__":
    main()
