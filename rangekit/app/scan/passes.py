"""Multi-pass scans on hardware: asking the user to turn the object over between turntable passes.

``rangekit scan --passes 2`` acquires a first pass, then the object must be turned over (to show its
bottom) before the second. On the simulator the simulated rig turns it over itself
(:meth:`rangekit.sim.SimRig.start_pass`); on a real rig :func:`turn_over_prompt` asks on the terminal and
waits for Enter. Without a terminal (standard input not a TTY: a batch job, a pipe) it cannot ask: the scan
stops with :class:`TurnOverNeeded` (exit 1) after every view of the finished pass is on disk, telling the
user to turn the object over and continue with ``rangekit scan --resume DIR --flipped`` (``--flipped``
confirms that the object has been turned over for the pass about to start).
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Callable, TextIO

from rangekit.errors import RangekitError

__all__ = ["TurnOverNeeded", "turn_over_prompt"]


class TurnOverNeeded(RangekitError):
    """A multi-pass scan reached the next pass where no one can be asked to turn the object over."""


def turn_over_prompt(folder: str | Path, passes: int, *, flipped: bool = False, stdin: TextIO | None = None,
                     stream: TextIO | None = None) -> Callable[[int], None]:
    """``turn_over(p)`` for :func:`rangekit.app.acquire.acquire.acquire` on hardware.

    ``flipped``: the user confirmed (``--flipped``) that the object is already turned over for the next
    pass; the first call returns at once. Otherwise, on a terminal (``stdin.isatty()``), the call prints what
    to do on ``stream`` (default stderr) and waits for Enter; with no terminal, or at the end of the input,
    it raises :class:`TurnOverNeeded` naming ``folder`` and the command that continues the scan.
    """
    confirmed = [bool(flipped)]

    def turn_over(p: int) -> None:
        if confirmed[0]:
            confirmed[0] = False
            return
        inp = sys.stdin if stdin is None else stdin
        out = sys.stderr if stream is None else stream
        again = (f"turn the object over on the turntable, then continue with: rangekit scan --resume {folder} "
                 "--flipped")
        isatty = getattr(inp, "isatty", None)
        if inp is None or isatty is None or not isatty():
            raise TurnOverNeeded(f"{folder}: pass {p} of {passes} is done and pass {p + 1} needs the object turned "
                                 f"over; standard input is not a terminal, so rangekit cannot wait for you: {again}")
        print(f"pass {p} of {passes} done. Turn the object over on the turntable (bottom up, near the centre), "
              f"then press Enter to scan pass {p + 1}", file=out, flush=True)
        if not inp.readline():      # end of input: no one answered
            raise TurnOverNeeded(f"{folder}: pass {p + 1} of {passes}: no answer (end of input); {again}")

    return turn_over
