"""The ``rangekit`` command line. Each command parses, converts human units, calls the library, prints.

Run ``rangekit --help`` or ``rangekit COMMAND --help``.
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from rangekit.errors import RangekitError

__all__ = ["main"]


def _say(msg: str) -> None:
    print(msg, flush=True)


def cmd_sim_render(args: argparse.Namespace) -> int:
    """rangekit sim render --object NAME_OR_MESH [--patterns graycode] --out DIR"""
    from dataclasses import replace

    from rangekit.patterns import make_pattern_spec
    from rangekit.rig import load_rig
    from rangekit.sim import ImagingModel, SimRig, default_scene
    from rangekit.sim.capture import write_capture

    t0 = time.perf_counter()
    imaging = ImagingModel(bits=args.bits)
    if args.no_noise:
        imaging = imaging.noiseless()
    if args.global_fraction is not None:
        imaging = replace(imaging, global_fraction=args.global_fraction)
    rig = load_rig(args.rig) if args.rig else None
    sim = SimRig(default_scene(args.object), rig, imaging=imaging, seed=args.seed)
    if sim.turntable is not None:
        sim.turntable.rotate_to(np.radians(args.angle_deg))
    spec = make_pattern_spec(args.patterns, sim.projector.resolution)
    write_capture(sim, spec, args.out, info={"object": args.object}, progress=_say)
    _say(f"done in {time.perf_counter() - t0:.1f} s")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="rangekit", description="Active 3D scanning: simulate, capture, "
                                     "decode, register and fuse range data.")
    parser.add_argument("--version", action="version", version=f"rangekit {__import__('rangekit').__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    sim = sub.add_parser("sim", help="simulated rig: render captures with exact ground truth",
                         description="Simulated projector-camera-turntable rig.")
    sim_sub = sim.add_subparsers(dest="sim_command", metavar="SUBCOMMAND")
    sim_sub.required = True
    render = sim_sub.add_parser(
        "render", help="render a pattern sequence on a simulated object and write captures + ground truth",
        description="Render the captures a real rig would take of an object, plus ground_truth.npz "
                    "(depth, xyz, normals, proj_col, proj_row, valid), the rig file and a preview PNG.")
    from rangekit.patterns import PATTERN_METHODS

    render.add_argument("--object", default="lumpy",
                        help="built-in object (plane, sphere, box, cylinder, torus, board, lumpy) or a mesh "
                             "file trimesh can read (metres); default: lumpy")
    render.add_argument("--patterns", default="graycode", choices=PATTERN_METHODS,
                        help="pattern set to project; default: graycode (44 frames on the default rig)")
    render.add_argument("--out", required=True, help="output folder (created if missing)")
    render.add_argument("--rig", help="rig file to simulate (default: the built-in simulated rig)")
    render.add_argument("--angle-deg", type=float, default=0.0, help="turntable angle in degrees (default 0)")
    render.add_argument("--bits", type=int, default=8, choices=(8, 10, 12, 16), help="camera bit depth")
    render.add_argument("--seed", type=int, default=0, help="noise seed (default 0)")
    render.add_argument("--no-noise", action="store_true", help="disable shot and read noise")
    render.add_argument("--global-fraction", type=float, default=None,
                        help="interreflection term, fraction of the mean projected light (default 0)")
    render.set_defaults(func=cmd_sim_render)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.func(args)
    except RangekitError as exc:
        print(f"rangekit: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("rangekit: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
