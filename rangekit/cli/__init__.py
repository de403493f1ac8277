"""The ``rangekit`` command line (entry point ``rangekit.cli:main``); see :mod:`rangekit.cli.run`.

:func:`main` imports the commands inside its own Ctrl-C handler, so an interrupt while numpy loads also
ends with exit 130 and one line, not a traceback.
"""

from __future__ import annotations

import sys

__all__ = ["build_parser", "main"]


def main(argv: list[str] | None = None) -> int:
    try:
        from rangekit.cli.run import main as run
    except KeyboardInterrupt:
        print("rangekit: interrupted", file=sys.stderr)
        return 130
    return run(argv)


def build_parser():
    from rangekit.cli.run import build_parser as build

    return build()
