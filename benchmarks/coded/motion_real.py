"""The coded-light motion check on still captures (issue 47: no still capture refused as moved) and on the
simulator's 0.5 mm slip (issue 38: its spoiled pixels caught).

    PYTHONPATH=. .venv/bin/python benchmarks/coded/motion_real.py [--no-sim] [--no-real] [--time]

Printed, one JSON line per capture: the share of the decoded pixels the ``motion`` mask flags
(:func:`rangekit.coded.decode.decode` with ``motion=True``, ``max_motion=None``; the decoded pixels are those of the
same decode without the check), and for the slip the share of its spoiled pixels flagged
(benchmarks/coded/bench_motion.py's definition); ``detect_share``: the share :func:`rangekit.coded.motion.detect_motion`
(what ``rangekit process`` and ``rangekit scan`` refuse a view by, over ``max_motion`` 2%) finds moved, and
``detect_share_every_bit``: the same reading every bit (``read_sigmas=0``, the rule before issue 47). The still
real captures are every binary-coded one in the shared
data (``$RANGEKIT_DATA`` or ``../shared/data``): SLStudio's skull under its Gray code (``slstudio:graycode``; its
calibration sequences are phase-shifted, not binary) and RoomAlive's Gray code (``roomalive:graycode``). The
simulated ones: the default rig and object still, with the projector and camera defocused (projector sigma 2 px,
camera 1.5 px), and with interreflection (30% of the direct light, blurred over 20 camera pixels). ``--time``: the
decode's CPU seconds with and without the check, and detect_motion's (best of 3) on the skull and the default rig.
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from rangekit.coded.decode import decode
from rangekit.coded.motion import detect_motion


def _cpu(f) -> float:
    best = np.inf
    for _ in range(3):
        c0 = time.process_time()
        f()
        best = min(best, time.process_time() - c0)
    return best


def flagged_share(stack, spec, options: dict) -> dict:
    """The motion mask's share of the decoded pixels of one capture, and what it flagged."""
    plain = decode(stack, spec, motion=False, **options)
    checked = decode(stack, spec, motion=True, max_motion=None, **options)
    decoded = np.isfinite(plain.proj_col)
    flagged = checked.motion & decoded
    return {"decoded": int(decoded.sum()), "flagged": int(flagged.sum()),
            "flagged_share": round(float(flagged.sum() / max(decoded.sum(), 1)), 5),
            "frames_named": list(checked.moved_frames), **detect_shares(stack, spec, decoded)}


def detect_shares(stack, spec, decoded: np.ndarray) -> dict:
    """detect_motion's share of a capture (``decoded``: its decoded pixels), with the rule of the bits read and
    with every bit read (before issue 47)."""
    return {"detect_share": round(detect_motion(stack, spec, decoded).share, 5),
            "detect_share_every_bit": round(detect_motion(stack, spec, decoded, read_sigmas=0.0).share, 5)}


def real_captures() -> dict:
    """name -> (stack, spec, decode options) of every still binary-coded real capture found."""
    from rangekit.formats.capture import read_stack
    from rangekit.formats.layouts import LAYOUTS, arrange, layout_files
    from rangekit.sim.scene.zoo import data_folders

    found = {}
    cases = {"slstudio-skull/skull_gray": ("slstudio:graycode", 1824, 1140),
             "roomalive/calibration/projector0/camera0": ("roomalive:graycode", 1400, 1050)}
    for name, (preset, w, h) in cases.items():
        folder = next((f / name for f in data_folders() if (f / name).is_dir()), None)
        if folder is None:
            continue
        layout = LAYOUTS[preset]
        stack, spec = arrange(list(read_stack(layout_files(folder, layout, w, h))), layout, w, h)
        found[f"{preset} ({name.split('/')[0]})"] = stack, spec, dict(layout.view_options.get("decode_options", {}))
    return found


def sim_cases() -> dict:
    """The simulated still captures and the slip: name -> result."""
    from rangekit.coded.patterns import make_pattern_spec
    from rangekit.sim import SimRig, default_rig, default_scene
    from rangekit.sim.devices.motion import Motion, capture_moving
    from rangekit.sim.imaging.render import ImagingModel
    from rangekit.sim.scene.passes import pass_scene

    rig = default_rig()
    spec = make_pattern_spec("graycode", (rig.projector.width, rig.projector.height))
    frames = list(spec.frames())
    out = {}
    for name, model in {"sim still": None,
                        "sim still, defocused": ImagingModel(projector_blur=2.0, camera_blur=1.5),
                        "sim still, interreflection": ImagingModel(global_fraction=0.3, global_blur=20.0)}.items():
        still = SimRig(default_scene(), rig, imaging=model, seed=5).capture_sequence(frames)
        out[name] = flagged_share(still, spec, {})
    motion = Motion("slip", 5e-4, direction=(1.0, 0.0, 0.0), at_frame=len(frames) // 2)
    moved_scene = pass_scene(default_scene(), motion.motion(len(frames)))
    still = SimRig(default_scene(), rig, seed=5).capture_sequence(frames)
    moved = SimRig(moved_scene, rig, seed=5).capture_sequence(frames)
    moving, _ = capture_moving(SimRig(default_scene(), rig, seed=5), frames, motion)
    t_still, t_moved = SimRig(default_scene(), rig).ground_truth(), SimRig(moved_scene, rig).ground_truth()
    ds, dv, dm = (decode(x, spec, motion=False) for x in (still, moved, moving))

    def worse(m, s, truth):
        return np.isfinite(m) & np.isfinite(truth) & (np.abs(m - truth) > np.nan_to_num(np.abs(s - truth), nan=0.0) + 0.5)

    spoiled = worse(dm.proj_col, ds.proj_col, t_still.proj_col) & worse(dm.proj_col, dv.proj_col, t_moved.proj_col)
    checked = decode(moving, spec, motion=True, max_motion=None)
    decoded = np.isfinite(dm.proj_col)
    out["sim 0.5 mm slip"] = {"spoiled": int(spoiled.sum()),
                              "spoiled_flagged": round(float((checked.motion & spoiled).sum() / max(spoiled.sum(), 1)), 4),
                              "flagged_share": round(float((checked.motion & decoded).sum() / decoded.sum()), 4),
                              "frames_named": list(checked.moved_frames),
                              **detect_shares(np.stack(moving), spec, np.isfinite(ds.proj_col))}
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--no-sim", action="store_true")
    ap.add_argument("--no-real", action="store_true")
    ap.add_argument("--time", action="store_true")
    args = ap.parse_args()
    real = {} if args.no_real else real_captures()
    for name, (stack, spec, options) in real.items():
        print(json.dumps({"capture": name, **flagged_share(stack, spec, options)}), flush=True)
    if not args.no_sim:
        for name, result in sim_cases().items():
            print(json.dumps({"capture": name, **result}), flush=True)
    if args.time:
        from rangekit.coded.patterns import make_pattern_spec
        from rangekit.sim import SimRig, default_rig, default_scene

        timed = {name: v for name, v in real.items() if name.startswith("slstudio")}
        rig = default_rig()
        spec = make_pattern_spec("graycode", (rig.projector.width, rig.projector.height))
        timed["sim still"] = SimRig(default_scene(), rig, seed=5).capture_sequence(list(spec.frames())), spec, {}
        for name, (stack, spec, options) in timed.items():
            decoded = np.isfinite(decode(stack, spec, motion=False, **options).proj_col)
            print(json.dumps({"timed": name, "decode_cpu_s": {
                "checked": round(_cpu(lambda: decode(stack, spec, motion=True, max_motion=None, **options)), 3),
                "unchecked": round(_cpu(lambda: decode(stack, spec, motion=False, **options)), 3)},
                "detect_motion_cpu_s": round(_cpu(lambda: detect_motion(stack, spec, decoded)), 3)}), flush=True)


if __name__ == "__main__":
    main()
