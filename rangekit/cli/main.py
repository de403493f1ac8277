"""The ``rangekit`` command line: the parser of every command, and :func:`main`.

Each command lives in the module of its group (``rangekit.cli.sim``, ``coded``, ``registration``,
``scan``, ``render``, ``rig``, ``photometric``, ``range``): it parses, converts human units, calls the
library, prints. Run ``rangekit --help`` or ``rangekit COMMAND --help``.
"""

from __future__ import annotations

import argparse
import sys

from rangekit.cli.coded import add_parsers as add_coded
from rangekit.cli.photometric import add_parsers as add_photometric
from rangekit.cli.range import add_parsers as add_range
from rangekit.cli.registration import add_parsers as add_registration
from rangekit.cli.render import add_parsers as add_render
from rangekit.cli.rig import add_calibrate_parser, add_parsers as add_rig
from rangekit.cli.scan import add_parsers as add_scan
from rangekit.cli.sim import add_parsers as add_sim
from rangekit.errors import RangekitError

__all__ = ["build_parser", "main"]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="rangekit", description="Active 3D scanning: simulate, capture, "
                                     "decode, register and fuse range data.")
    parser.add_argument("--version", action="version", version=f"rangekit {__import__('rangekit').__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    add_sim(sub)
    add_coded(sub)
    add_registration(sub)
    add_scan(sub)
    add_render(sub)
    add_calibrate_parser(sub)
    add_photometric(sub)
    add_range(sub)
    add_rig(sub)
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
