"""What every command shares: printing, progress on the console, the WIDTHxHEIGHT argument type."""

from __future__ import annotations

import argparse
import sys


def say(msg: str) -> None:
    print(msg, flush=True)


def console():
    """Progress for long stages: a bar on a terminal, plain lines in CI, pipes and files."""
    from rangekit.progress import Console

    return Console(sys.stdout)


def size(text: str) -> tuple[int, int]:
    """Argument type for image, sensor and projector sizes: WIDTHxHEIGHT in pixels."""
    try:
        w, h = (int(v) for v in text.lower().split("x"))
        if w > 0 and h > 0:
            return w, h
    except ValueError:
        pass
    raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT in pixels, e.g. 1280x800, found {text!r}")
