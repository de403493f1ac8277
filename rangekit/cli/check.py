"""rangekit check: look before scanning (saturation, dark pixels, contrast, exposure, projector latency,
one test view), on the simulator or on the rig file's hardware."""

from __future__ import annotations

import argparse
import time

from rangekit.cli._common import check_output, console, float_in, result as final, say, seed
from rangekit.errors import UsageError
from rangekit.formats.output_sets import claim_folder
from rangekit.formats.sessions.files import RIG_FILE


def cmd_check(args: argparse.Namespace) -> int:
    """rangekit check [--rig RIG.json] [--out DIR] [--object shiny] [--seed N] [--latency-ms 50]"""
    from rangekit.app.check.run import (check_hardware, check_simulated, simulated_check_rig, write_check,
                                        write_pattern_delay)

    t0 = time.perf_counter()
    replace = lambda: []  # noqa: E731
    if args.out is not None:
        check_output(args.out, option="--out", folder=True)
        simulated = args.rig in (None, "sim")
        replace = claim_folder(args.out, "check", force=args.force, inputs=[None if simulated else args.rig],
                               names=("check.json", "check.png") + ((RIG_FILE,) if simulated else ()))
    hardware = args.rig not in (None, "sim")
    if hardware:
        given = [opt for opt, v in (("--object", args.object), ("--seed", args.seed),
                                    ("--latency-ms", args.latency_ms)) if v is not None]
        if given:
            raise UsageError(f"{', '.join(given)}: simulator options; a check of --rig {args.rig} looks at the real "
                             "object and measures the real latency: leave them out")
        check_output(args.rig, option="--rig", force=True)   # its pattern delay is rewritten in place
        result, images, rig = check_hardware(args.rig, progress=console())
        if not hasattr(result, "pattern_delay_s"):     # a camera without a projector display: the camera alone
            return _camera_only(args, result, images, replace, t0)
        written = write_pattern_delay(args.rig, result.pattern_delay_s, result.flush_frames)
        rig_note = f"wrote {' and '.join(written)} into {args.rig} (no other field changed)"
        full_scale, out_rig = float((1 << int(rig.capture.get("bits", 8))) - 1), None
    else:
        from rangekit.sim import SimRig, default_scene

        sim = SimRig(default_scene(args.object or "lumpy"), seed=args.seed or 0,
                     latency_s=(50.0 if args.latency_ms is None else args.latency_ms) / 1e3)
        result, images = check_simulated(sim, progress=console())
        out_rig = simulated_check_rig(sim, result.pattern_delay_s)
        full_scale = float(sim.imaging.max_value)
        rig_note = (f"wrote {args.out}/{RIG_FILE} with capture.pattern_delay_s {result.pattern_delay_s:g}"
                    if args.out else "give --out DIR to write the rig file with the measured delay")
    s = result.stats
    say("")
    say(f"object: {s.n_object} pixels; saturated under white: {s.saturated_fraction:.2%} ("
        + ", ".join(f"{k} {v:.2%}" for k, v in s.channel_saturation.items()) + ")")
    say(f"too dark to decode (white - black < 3% of full scale): {s.dark_fraction:.2%}")
    say("white - black over the object: " + ", ".join(f"{k} {v:.1%}" for k, v in s.contrast_percentiles.items()))
    counts, edges = s.histogram
    top = max(max(counts), 1)
    for c, lo, hi in zip(counts, edges[:-1], edges[1:]):
        if c:
            say(f"  {lo:4.0%}-{hi:4.0%} {'#' * max(1, round(40 * c / top)):40s} {c}")
    say(f"latency: {', '.join(f'{x * 1e3:.0f}' for x in result.latencies_s)} ms (frame period "
        f"{result.frame_period_s * 1e3:.1f} ms)")
    say(f"test view: {result.points} points" + ("" if result.rms_m is None else
                                                 f", RMS {result.rms_m * 1e3:.3f} mm against the truth"))
    for line in result.advice():
        say(line)
    if args.out:
        names = write_check(args.out, result, images, full_scale, out_rig)
        replace()
        say(f"wrote {', '.join(f'{args.out}/{n}' for n in names)}")
    say(rig_note)
    final(f"check took {time.perf_counter() - t0:.1f} s")
    return 0


def _camera_only(args: argparse.Namespace, result, images: dict, replace, t0: float) -> int:
    """The camera check's lines and files (rangekit.app.check.camera); the rig file is not changed."""
    from rangekit.app.check.run import write_check

    say("")
    for line in result.lines():
        say(line)
    if args.out:
        names = write_check(args.out, result, images, 0.0)
        replace()
        say(f"wrote {', '.join(f'{args.out}/{n}' for n in names)}")
    final(f"check took {time.perf_counter() - t0:.1f} s")
    return 0


def add_parsers(sub) -> None:
    p = sub.add_parser("check", help="look before scanning: saturation, dark pixels, exposure, projector latency, "
                                     "one test view",
                       description="Project white, black and a checker; report saturation, dark pixels and the "
                                   "contrast histogram, suggest an exposure, measure the projector-to-camera latency "
                                   "(written into the rig file's capture.pattern_delay_s) and reconstruct one "
                                   "coded-light view. On the simulator by default, on hardware with --rig.")
    p.add_argument("--rig", help="'sim' (default) or a rig file whose 'devices' name the projector and camera; its "
                                 "capture.pattern_delay_s is rewritten with the measured delay")
    p.add_argument("--out", help=f"folder for check.png, check.json (and, on the simulator, {RIG_FILE})")
    p.add_argument("--force", action="store_true", help="write over files in --out this run did not make: another command's set (a session, a capture, results), files of yours, an input")
    p.add_argument("--object", help="simulated object (default lumpy; 'shiny' saturates)")
    p.add_argument("--seed", type=seed, help="simulator noise seed (default 0)")
    p.add_argument("--latency-ms", type=float_in(0.0, 1000.0), help="the simulated projector's latency, ms "
                                                                   "(default 50)")
    p.set_defaults(func=cmd_check)
