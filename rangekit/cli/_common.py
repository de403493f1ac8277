"""What every command shares: printing, progress on the console, argument types that refuse bad values
at parse time (exit 2), and the check that an output path can be written before any work starts."""

from __future__ import annotations

import argparse
import logging
import math
import os
import re
import shutil
import sys
from pathlib import Path

from rangekit.budget import MAX_IMAGE_SIDE_PX as MAX_SIZE_PX
from rangekit.errors import FileFormatError, UsageError
from rangekit.formats.sessions.files import SESSION_FILE

#: Free space an output folder needs before a command starts, bytes.
MIN_FREE_BYTES = 64 * 2**20


def configure_logging(verbose: int = 0, quiet: bool = False) -> int:
    """Set the ``rangekit`` logger for one command: ``quiet`` (``-q``) WARNING: only errors and the final result
    line; default INFO: progress on standard error, reports on standard output; ``verbose`` (``-v``) DEBUG:
    every progress step and the library's details. Its one handler writes to the current standard error
    (above an open progress bar). Returns the level."""
    from rangekit.progress import LOGGER

    level = logging.WARNING if quiet else logging.DEBUG if verbose else logging.INFO
    LOGGER.setLevel(level)
    for h in [h for h in LOGGER.handlers if isinstance(h, _StderrHandler)]:
        LOGGER.removeHandler(h)
    LOGGER.addHandler(_StderrHandler())
    LOGGER.propagate = False
    return level


class _StderrHandler(logging.Handler):
    """Log records as lines on the standard error of the moment (tqdm.write: above an open bar); warnings
    and errors as ``rangekit: warning: ...``."""

    def emit(self, record: logging.LogRecord) -> None:
        try:
            msg = record.getMessage()
            if record.levelno >= logging.WARNING:
                msg = f"rangekit: {record.levelname.lower()}: {msg}"
            from tqdm import tqdm

            tqdm.write(msg, file=sys.stderr)
        except Exception:  # noqa: BLE001 - logging must never end a command
            self.handleError(record)


def _informative() -> bool:
    from rangekit.progress import LOGGER

    return LOGGER.isEnabledFor(logging.INFO)


def say(msg: str) -> None:
    """A report line on standard output (a table row, a figure); none with ``-q``."""
    if _informative():
        _print_out(msg)


def result(msg: str) -> None:
    """A command's final result line on standard output, printed even with ``-q``."""
    _print_out(msg)


def _print_out(msg: str) -> None:
    """One line on standard output; a failed write (``> /dev/full``) is an OSError naming standard output."""
    try:
        print(msg, flush=True)
    except BrokenPipeError:
        raise
    except OSError as exc:
        raise OSError(exc.errno, exc.strerror, "standard output") from None


def note(msg: str) -> None:
    """A progress message on standard error (``progress=note`` for steps without counts); none with ``-q``."""
    from rangekit.progress import LOGGER

    LOGGER.info(msg)


def console():
    """Progress for long stages on standard error: a tqdm bar with an ETA on a terminal, plain lines in CI,
    pipes and files, nothing with ``-q`` (:class:`rangekit.progress.Console`)."""
    from rangekit.progress import Console

    return Console(sys.stderr)


def size(text: str) -> tuple[int, int]:
    """Argument type for image, sensor and projector sizes: WIDTHxHEIGHT in pixels, each MIN_IMAGE_SIDE_PX ..
    MAX_SIZE_PX (the rig file's one rule, rangekit.rig.plausibility)."""
    from rangekit.rig.plausibility import MIN_IMAGE_SIDE_PX

    try:
        w, h = (int(v) for v in text.lower().split("x"))
        if MIN_IMAGE_SIDE_PX <= w <= MAX_SIZE_PX and MIN_IMAGE_SIDE_PX <= h <= MAX_SIZE_PX:
            return w, h
    except ValueError:
        pass
    raise argparse.ArgumentTypeError(f"expected WIDTHxHEIGHT in pixels, each {MIN_IMAGE_SIDE_PX}..{MAX_SIZE_PX}, e.g. "
                                     f"1280x800, found {text!r}")


def _number(kind, text: str, test, expected: str):
    try:
        value = kind(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {expected}, found {text!r}") from None
    if not (math.isfinite(value) and test(value)):
        raise argparse.ArgumentTypeError(f"expected {expected}, found {text!r}")
    return value


def positive_float(text: str) -> float:
    """Argument type: a finite number > 0."""
    return _number(float, text, lambda v: v > 0, "a finite number > 0")


def non_negative_float(text: str) -> float:
    """Argument type: a finite number >= 0."""
    return _number(float, text, lambda v: v >= 0, "a finite number >= 0")


def float_in(lo: float, hi: float):
    """Argument type factory: a finite number in [lo, hi]."""
    def parse(text: str) -> float:
        return _number(float, text, lambda v: lo <= v <= hi, f"a number in {lo:g}..{hi:g}")
    parse.__name__ = f"float_{lo:g}_{hi:g}"
    return parse


def finite_float(text: str) -> float:
    """Argument type: any finite number (no nan, no inf)."""
    return _number(float, text, lambda v: True, "a finite number")


#: Argument type: a number in [0, 1].
fraction = float_in(0.0, 1.0)


def scheduler_address(text: str) -> str:
    """Argument type of --scheduler: 'local' or a Dask scheduler address, tcp://HOST:PORT."""
    if text == "local" or re.fullmatch(r"(tcp|tls|ws|wss|inproc)://\[?[\w.:-]+\]?:\d{1,5}", text):
        return text
    raise argparse.ArgumentTypeError(f"expected 'local' or a Dask scheduler address tcp://HOST:PORT, found {text!r}")


def int_in(lo: int, hi: int):
    """Argument type factory: an integer in [lo, hi]."""
    def parse(text: str) -> int:
        return _number(int, text, lambda v: lo <= v <= hi, f"an integer in {lo}..{hi}")
    parse.__name__ = f"int_{lo}_{hi}"
    return parse


def seed(text: str) -> int:
    """Argument type: a random seed, 0 <= seed < 2**32 (what numpy accepts)."""
    return int_in(0, 2**32 - 1)(text)


def check_output(path: str | os.PathLike, *, option: str = "--out", folder: bool = False,
                 force: bool = False, session: bool = False, suffixes=None, what: str = "output",
                 inputs=()) -> Path:
    """Check before any work that ``path`` can be written: a file where a file is expected (not an existing
    folder), a folder where a folder is expected, its nearest existing parent a writable folder with at
    least :data:`MIN_FREE_BYTES` free. Raises :class:`UsageError` naming the option and the path; with
    ``session=True`` the folder is also read (a session to resume or process), so a file there is bad data
    (:class:`FileFormatError`, exit 1). ``suffixes``: the extensions a file output may have (the formats
    module's own list, e.g. ``MESH_FORMATS``), ``what`` names them in the error.

    A file output that exists is written over only with ``force`` (the command's ``--force``): a named file
    is never this run's own output, and it may be one of the command's ``inputs`` (compared resolved) or
    belong to another command's set of files (:func:`rangekit.formats.output_sets.file_owner`); the error
    says which. A folder's files are claimed by :func:`rangekit.formats.output_sets.claim_folder`."""
    raw = os.fsdecode(path)
    if not raw:
        raise UsageError(f"{option}: an empty path; expected a {'folder' if folder else 'file name'}")
    if not folder and raw.endswith(("/", os.sep)):
        raise UsageError(f"{option} {raw}: ends with '/', which names a folder; expected a file name")
    too_long = next((part for part in raw.split(os.sep) if len(os.fsencode(part)) > 255), None)
    if too_long is not None or len(os.fsencode(raw)) > 4095:
        raise UsageError(f"{option} {raw[:60]}...: a name longer than the system allows (255 bytes a name, 4095 a "
                         f"path); choose a shorter one")
    out = Path(path)
    if folder and out.exists() and not out.is_dir():
        if session:
            raise FileFormatError(f"{out}: expected a session folder (with {SESSION_FILE}), found a file")
        raise UsageError(f"{option} {out}: expected a folder, found an existing file")
    if not folder and out.is_dir():
        raise UsageError(f"{option} {out}: expected a file name, found an existing folder")
    if suffixes is not None and out.suffix.lower() not in suffixes:
        raise UsageError(f"{option} {out}: expected a {what} file ({', '.join(suffixes)}), found "
                         f"{repr(out.suffix) if out.suffix else 'no extension'}")
    if not folder and (out.exists() or out.is_symlink()) and not force:
        raise UsageError(f"{option} {out}: {_existing_file(out, inputs)}; choose another file, or pass --force to "
                         f"overwrite it")
    parent = out if folder and out.is_dir() else out.parent
    parent = parent.resolve()
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise UsageError(f"{option} {out}: {parent} is a file, not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise UsageError(f"{option} {out}: the folder {parent} is not writable")
    free = shutil.disk_usage(parent).free
    if free < MIN_FREE_BYTES:
        raise UsageError(f"{option} {out}: only {free / 2**20:.1f} MB free on the disk of {parent}; "
                         f"expected at least {MIN_FREE_BYTES / 2**20:.0f} MB")
    return out


def _existing_file(out: Path, inputs) -> str:
    """What an existing output file is, for the refusal: one of the inputs, another command's, or just there."""
    from rangekit.formats.output_sets import file_owner, same_file

    given = same_file(out, [p for p in inputs if p is not None])
    if given is not None:
        if Path(given).resolve() == out.resolve():
            return f"is this command's input {given}"
        return f"exists in this command's input folder {given}"
    owner = file_owner(out)
    if owner is not None:
        return f"exists and belongs to {owner.what} ({next(m for m in owner.markers if (out.parent / m).is_file())})"
    return "exists"


def check_beside(out: str | os.PathLike, names, *, force: bool, option: str = "--out", inputs=()) -> None:
    """The files a command writes beside its ``--out`` file (``coverage.png``, ``<stem>.refined-rig.json``),
    checked as ``--out`` is: one that exists is written over only with ``force``. UsageError naming it."""
    out = Path(out)
    for name in names:
        side = out.with_name(name)
        if (side.exists() or side.is_symlink()) and not force:
            raise UsageError(f"{option} {out}: {side}, written beside it, {_existing_file(side, inputs)}; choose "
                             f"another --out folder, or pass --force to overwrite it")


class LazyChoices:
    """argparse ``choices`` read from ``module.name`` only when an option is checked or help is shown, so
    building the parser does not import the module (give the option a ``metavar``: argparse lists plain
    choices at ``add_argument``). ``rangekit decode`` starts without importing ``rangekit.app``."""

    def __init__(self, module: str, name: str):
        self.module, self.name = module, name

    def _values(self):
        import importlib

        return getattr(importlib.import_module(self.module), self.name)

    def __contains__(self, value) -> bool:
        return value in self._values()

    def __iter__(self):
        return iter(self._values())

    def __len__(self) -> int:
        return len(self._values())


def _load(path: str):
    """``"module:NAME"`` -> the module's ``NAME``, imported now."""
    import importlib

    module, _, name = path.partition(":")
    return getattr(importlib.import_module(module), name)


class LazyHelp(argparse.HelpFormatter):
    """Help strings whose ``{name}`` fields are filled when help is shown, from the action's ``help_values``
    (``"module:FUNCTION"``, called for a dict), so that building the parser imports nothing the values come from
    (``rangekit decode`` starts without importing ``rangekit.app``; :func:`lazy_help`)."""

    def _get_help_string(self, action) -> str:
        text = super()._get_help_string(action)
        values = getattr(action, "help_values", None)
        return text if values is None else text.format(**_load(values)())


def lazy_help(action: argparse.Action, values: str) -> argparse.Action:
    """``action``'s help filled by ``values`` (``"module:FUNCTION"``) when shown (:class:`LazyHelp`)."""
    action.help_values = values
    return action


def option_range(options: str, field: str):
    """Argument type: an integer in the range of field ``field`` of the options dataclass ``options``
    (``"module:Class"``, its metadata: :mod:`rangekit._runtime.option_fields`), read on the first value parsed."""
    def parse(text: str) -> int:
        from rangekit._runtime.option_fields import specs

        s = specs(_load(options))[field]
        return int_in(s.lo, s.hi)(text)
    parse.__name__ = f"{field}_range"
    return parse
