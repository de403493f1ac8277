"""The ``rangekit`` command line: the parser of every command, and :func:`main`.

Each command lives in the module of its group (``rangekit.cli.sim``, ``coded``, ``registration``,
``scan``, ``render``, ``rig``, ``photometric``, ``range``): it parses, converts human units, calls the
library, prints. Run ``rangekit --help`` or ``rangekit COMMAND --help``.
"""

from __future__ import annotations

import argparse
import errno
import os
import sys

from rangekit.cli._common import configure_logging
from rangekit.cli.check import add_parsers as add_check
from rangekit.cli.ui import add_parsers as add_ui
from rangekit.cli.coded import add_parsers as add_coded
from rangekit.cli.photometric import add_parsers as add_photometric
from rangekit.cli.range import add_parsers as add_range
from rangekit.cli.registration import add_parsers as add_registration
from rangekit.cli.render import add_parsers as add_render
from rangekit.cli.rig import add_calibrate_parser, add_parsers as add_rig
from rangekit.cli.scan import add_parsers as add_scan
from rangekit.cli.sim import add_parsers as add_sim
from rangekit.errors import RangekitError, UsageError, bounded_message
from rangekit._runtime.environment import interrupted, memory_shortage
from rangekit._runtime.open3d_viewer import defer_plotly_viewer
from rangekit._runtime.threads import one_blas_thread

__all__ = ["build_parser", "main", "EXIT_OK", "EXIT_FAILURE", "EXIT_USAGE", "EXIT_INTERRUPTED"]

EXIT_OK, EXIT_FAILURE, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130


class _Parser(argparse.ArgumentParser):
    """argparse with rangekit's error line: ``rangekit: error: COMMAND: MESSAGE`` after the usage, exit 2."""

    def error(self, message: str):
        self.print_usage(sys.stderr)
        command = self.prog.partition(" ")[2]
        self.exit(EXIT_USAGE, f"rangekit: error: {command + ': ' if command else ''}{message}\n")


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="rangekit", description="Active 3D scanning: simulate, capture, "
                                     "decode, register and fuse range data.")
    parser.add_argument("--version", action="version", version=f"rangekit {__import__('rangekit').__version__}")
    _add_verbosity(parser, argparse.SUPPRESS)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    add_sim(sub)
    add_coded(sub)
    add_registration(sub)
    add_scan(sub)
    add_check(sub)
    add_render(sub)
    add_calibrate_parser(sub)
    add_photometric(sub)
    add_range(sub)
    add_rig(sub)
    add_ui(sub)
    for command in _leaf_parsers(parser):
        _add_verbosity(command, argparse.SUPPRESS)
    return parser


def _add_verbosity(parser: argparse.ArgumentParser, default) -> None:
    """``-v/--verbose`` and ``-q/--quiet``, before the command or after it (``default=SUPPRESS``: a command
    that does not repeat them keeps the values given before it)."""
    parser.add_argument("-v", "--verbose", action="store_true", default=default,
                        help="debug details: every progress step and the library's log")
    parser.add_argument("-q", "--quiet", action="store_true", default=default,
                        help="only errors and the final result line")


def _leaf_parsers(parser: argparse.ArgumentParser):
    """Every parser below ``parser`` that runs a command (``rangekit rig init``, not ``rangekit rig``)."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for child in dict.fromkeys(action.choices.values()):    # aliases share their parser
                yield child
                yield from _leaf_parsers(child)


def _verbosity(args: argparse.Namespace) -> None:
    verbose, quiet = getattr(args, "verbose", False), getattr(args, "quiet", False)
    if verbose and quiet:
        raise UsageError("-v/--verbose and -q/--quiet: expected one of them, found both")
    configure_logging(verbose=verbose, quiet=quiet)


def main(argv: list[str] | None = None) -> int:
    """Run one command; return its exit code: 0 done, 1 runtime failure (bad data, device fault, I/O),
    2 usage error (bad option, unusable output path), 130 interrupted. Never a traceback, unless the
    environment sets ``RANGEKIT_DEBUG=1`` (then unexpected exceptions propagate)."""
    defer_plotly_viewer()   # rangekit's process: Open3D's plotly viewer imported only if called (0.2-0.4 CPU-s, 42 MB)
    try:
        args = build_parser().parse_args(argv)
        _verbosity(args)
        with one_blas_thread():     # thin products dominate: see rangekit._runtime.threads
            return args.func(args)
    except UsageError as exc:
        return _fail(str(exc), EXIT_USAGE)
    except RangekitError as exc:
        return _fail(str(exc), EXIT_FAILURE)
    except KeyboardInterrupt:
        print("rangekit: interrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        _detach_stdout()
        return _fail("standard output was closed before the output was written", EXIT_FAILURE)
    except (OSError, MemoryError, Exception) as exc:
        if interrupted():   # Ctrl-C inside a lazy import shows as "ImportError: initialization failed"
            print("rangekit: interrupted", file=sys.stderr)
            return EXIT_INTERRUPTED
        if memory_shortage(exc):   # under a low ulimit -v: a library that cannot map, an image not allocated
            return _fail(memory_shortage(exc), EXIT_FAILURE)
        if isinstance(exc, OSError):
            return _fail(_os_message(exc), EXIT_FAILURE)
        if isinstance(exc, MemoryError):
            return _fail("out of memory; use smaller images, fewer views or a larger --voxel-mm", EXIT_FAILURE)
        if os.environ.get("RANGEKIT_DEBUG") == "1":   # the last net: a bug, in one line, never a traceback
            raise
        return _fail(f"internal error ({type(exc).__name__}: {str(exc)[:200]}); please report it with the "
                     "command line (RANGEKIT_DEBUG=1 shows the traceback)", EXIT_FAILURE)


def _fail(message: str, code: int) -> int:
    try:
        print(f"rangekit: error: {bounded_message(message)}", file=sys.stderr, flush=True)
    except OSError:
        pass
    return code


def _os_message(exc: OSError) -> str:
    """An OSError in one line naming the file; a full disk says so."""
    where = exc.filename if exc.filename is not None else "a file"
    if where == "standard output":   # rangekit.cli._common: a result line that could not be written
        _detach_stdout()
        return f"standard output: cannot be written ({exc.strerror}); send it to a file or a pipe that takes it"
    if exc.errno in (errno.ENOSPC, errno.EFBIG, errno.EDQUOT):
        return (f"{where}: no space left to write ({exc.strerror}); free some space, then run the command again "
                "(a scan continues with: rangekit scan --resume DIR)")
    return f"{where}: {exc.strerror or exc}"


def _detach_stdout() -> None:
    """After a broken pipe, point stdout at /dev/null so the interpreter's final flush stays quiet."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):
        pass


if __name__ == "__main__":
    sys.exit(main())
