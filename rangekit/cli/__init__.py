"""The ``rangekit`` command line (entry point ``rangekit.cli:main``); see :mod:`rangekit.cli.run`.

:func:`main` checks the surroundings first (:mod:`rangekit._runtime.environment`), then imports the commands
inside its own Ctrl-C handler, so an interrupt while numpy loads also ends with exit 130 and one line, not
a traceback.
"""

from __future__ import annotations

import sys

__all__ = ["build_parser", "main"]


def main(argv: list[str] | None = None) -> int:
    from rangekit._runtime.environment import prepare, problems, watching_interrupts

    prepare()
    kind, message = problems()   # a deleted working folder, NUMBA_NUM_THREADS=abc, ulimit -v too low
    if message:
        print(f"rangekit: error: {message}", file=sys.stderr)
        return 2 if kind == "usage" else 1
    try:
        with watching_interrupts():
            return _run(argv)
    except KeyboardInterrupt:   # a SIGINT delivered while the handlers were being put back
        from rangekit._runtime.environment import interrupted

        if not interrupted():
            print("rangekit: interrupted", file=sys.stderr)
        return 130


def _run(argv: list[str] | None) -> int:
    from rangekit._runtime.environment import interrupted, memory_shortage

    try:
        from rangekit.cli.run import main as run
    except KeyboardInterrupt:
        print("rangekit: interrupted", file=sys.stderr)
        return 130
    except (ImportError, OSError, MemoryError) as exc:
        if interrupted():     # Ctrl-C inside a C extension's initialisation: "ImportError: initialization failed"
            print("rangekit: interrupted", file=sys.stderr)
            return 130
        shortage = memory_shortage(exc)
        if not shortage:
            raise
        print(f"rangekit: error: {shortage}", file=sys.stderr)
        return 1
    return run(argv)


def build_parser():
    from rangekit.cli.run import build_parser as build

    return build()
