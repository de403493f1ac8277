"""The rangekit exception hierarchy.

Every error a user can cause (a bad file, a bad argument, a device that does not answer) is raised as
one of these, with a message that names the input, what was expected and what was found. The CLI
catches :class:`RangekitError`, prints ``rangekit: error: MESSAGE`` and exits 2 for a
:class:`UsageError` (a bad option), 1 for anything else, without a traceback.
"""

from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator

__all__ = [
    "naming",
    "RangekitError",
    "InputError",
    "ArgumentTypeError",
    "UsageError",
    "OptionError",
    "BudgetError",
    "BudgetUsageError",
    "FileFormatError",
    "SceneError",
    "PatternError",
    "ConfigError",
    "DecodeError",
    "MotionError",
    "CalibrationError",
    "RegistrationError",
    "MeshError",
    "DeviceError",
    "DeviceTimeout",
    "DeviceDisconnected",
    "MissedTrigger",
    "ProtocolError",
    "CommandError",
    "StorageError",
    "QUOTE_LIMIT",
    "quote",
    "one_line",
    "SHOWN_LIMIT",
    "shown",
    "MESSAGE_LIMIT",
    "bounded_message",
]


class RangekitError(Exception):
    """Base of every error rangekit raises on purpose."""


class InputError(RangekitError, ValueError):
    """An argument has the wrong shape, type or value."""


class ArgumentTypeError(InputError, TypeError):
    """An argument of the wrong type: None where a value is needed, a string where a number or a flag is, a number
    where a path is (:mod:`rangekit._runtime.arguments`, the front door's checks). An :class:`InputError`, so the
    CLI and ``except RangekitError`` take it as any other bad input; and a ``TypeError``, as Python's own functions
    raise for a wrong type, so ``except TypeError`` written against the call still catches it."""


class UsageError(InputError):
    """A command-line option has a bad value or names an output that cannot be written (the CLI exits 2;
    every other :class:`RangekitError` is a runtime failure and exits 1)."""


class OptionError(UsageError):
    """A bad value of a job's options (:class:`rangekit.app.scan.options.ScanOptions`,
    :class:`rangekit.app.process.options.ProcessOptions`). ``template`` names the options as ``{field}`` placeholders
    (a section's field as ``{section.field}``): the message shows the Python field names (``views``,
    ``processing.poisson_depth``), and the command line re-raises it with its flags (:meth:`named`: ``--views``)."""

    def __init__(self, template: str) -> None:
        self.template = template
        super().__init__(self._render({}))

    def _render(self, names: dict) -> str:
        import re

        return re.sub(r"\{([a-z_.]+)\}", lambda m: names.get(m.group(1), m.group(1)), self.template)

    def within(self, section: str) -> "OptionError":
        """The same error with each ``{field}`` a field of ``section`` (``{processing.field}``): a section's error
        as the enclosing options name it."""
        import re

        return OptionError(re.sub(r"\{([a-z_.]+)\}", lambda m: f"{{{section}.{m.group(1)}}}", self.template))

    def named(self, names: dict) -> "OptionError":
        """The same error, each ``{field}`` shown as ``names[field]`` (a field not in ``names`` as itself)."""
        error = OptionError(self.template)
        error.args = (self._render(names),)
        return error


class BudgetError(InputError):
    """An input (a file's header, a spec's sizes) asks for more memory or work than rangekit allows: the
    memory budget of :mod:`rangekit.budget`, or a documented size limit. Raised before allocating."""


class BudgetUsageError(UsageError, BudgetError):
    """A command-line option asks for more memory than the budget allows (the CLI exits 2)."""


class FileFormatError(InputError):
    """A file is missing, unreadable, or not of the expected format."""


class SceneError(InputError):
    """A simulated scene cannot be built or seen (empty mesh, camera that sees nothing)."""


class MissingDataError(SceneError):
    """The shared real data a built-in object or a figure needs (../shared/data, ``$RANGEKIT_DATA``) is not there;
    the message names the file and the folders looked in (tests skip on it, naming them)."""


class PatternError(InputError):
    """A pattern image or pattern spec does not fit the projector or the capture."""


class ConfigError(InputError):
    """A rig file or settings file has a missing or invalid field."""


class DecodeError(RangekitError):
    """A capture stack cannot be decoded into projector coordinates."""


class MotionError(DecodeError):
    """The object moved during a coded-light capture (rangekit.coded.motion): the view must be captured again."""


class CalibrationError(RangekitError):
    """A calibration cannot be computed (too few views, degenerate poses)."""


class RegistrationError(RangekitError):
    """Scans cannot be registered (empty, no overlap)."""


class MeshError(RangekitError):
    """A mesh cannot be built or closed (too little data, a hole that cannot be filled)."""


class DeviceError(RangekitError):
    """A device (real or simulated) failed or is missing."""


class DeviceTimeout(DeviceError):
    """A device did not answer within its deadline."""


class DeviceDisconnected(DeviceError):
    """A device went away (unplugged, port closed)."""


class MissedTrigger(DeviceError):
    """A triggered camera's frame is not the one of the trigger expected (a trigger it missed, or a frame
    left over from another): the frame is never taken as the wrong one; the view is taken again."""


class ProtocolError(DeviceError):
    """A device answered something the protocol does not allow."""


class CommandError(DeviceError):
    """A device understood a command and refused it."""


class StorageError(RangekitError):
    """A file cannot be written (disk full, file too large, read-only); what was finished is kept."""


@contextmanager
def naming(source) -> Iterator[None]:
    """Name ``source`` (a file or folder) in the :class:`RangekitError` raised inside the block.

    Library functions that see only arrays (a cloud, a stack of images) cannot name the file the data came
    from; the code that read the file wraps the call, and the error is re-raised as the same type with
    ``"SOURCE: "`` in front of its message (unless the message starts with it already, as errors about a file
    inside a folder ``SOURCE/...`` do).
    """
    try:
        yield
    except RangekitError as exc:
        text = str(source)
        if str(exc).startswith(text):
            raise
        raise type(exc)(f"{text}: {exc}") from exc


#: The most characters (or bytes) of outside text an error message quotes: a device's reply, a line of a file.
QUOTE_LIMIT = 200


def quote(data: bytes | bytearray | str, limit: int = QUOTE_LIMIT) -> str:
    """``repr`` of at most ``limit`` bytes (characters) of ``data`` for an error message, so control
    characters and binary are escaped and a huge reply cannot flood the terminal: ``b'ok'``, or
    ``b'xxx...'... (10000 bytes)`` when longer.
    """
    if isinstance(data, bytearray):
        data = bytes(data)
    if len(data) <= limit:
        return repr(data)
    unit = "characters" if isinstance(data, str) else "bytes"
    return f"{data[:limit]!r}... ({len(data)} {unit})"


#: The most characters of a found value (a matrix, a list, a repr) an error message shows.
SHOWN_LIMIT = 80
#: The most characters of an error message the command line prints (its start and its end).
MESSAGE_LIMIT = 2000


def shown(value, limit: int = SHOWN_LIMIT) -> str:
    """A found value for an error message in at most about ``limit`` characters: its ``repr`` (an array or
    a numpy number as a list, rounded to 6 significant digits), cut with ``...`` and how big it was when
    longer: ``[[1.0, 0.0, 320.0], [0.0, 1.0, 24 ... (shape (300, 300))]``. Every matrix, vector or list an
    error quotes goes through it (issue 48: a 300 x 300 "camera matrix" made a 710 kB line)."""
    size = None
    if hasattr(value, "tolist") and hasattr(value, "shape"):   # numpy, without importing it here
        size = f"shape {tuple(value.shape)}"
        try:
            value = value.round(6) if value.dtype.kind == "f" else value
        except (AttributeError, TypeError):
            pass
        value = value.tolist()
    elif isinstance(value, (list, tuple)):
        size = f"{len(value)} items"
    text = repr(value)
    if len(text) <= limit:
        return text
    tail = f" ... ({size or f'{len(text)} characters'})"
    return text[:max(limit - len(tail), 20)] + tail


def bounded_message(message: str, limit: int = MESSAGE_LIMIT) -> str:
    """``message`` in at most about ``limit`` characters (its start and its end, where the found value and the
    way out are), so that no error fills a terminal: the command line's last net behind :func:`shown`."""
    if len(message) <= limit:
        return message
    half = (limit - 40) // 2
    return f"{message[:half]} ... ({len(message) - 2 * half} characters left out) ... {message[-half:]}"


def one_line(exc: BaseException | str, limit: int = QUOTE_LIMIT) -> str:
    """A library's error text (depthai's, pygame's, pyserial's) for a rangekit message: its whitespace and line
    breaks collapsed to single spaces, at most ``limit`` characters (then ``...``)."""
    text = " ".join(str(exc).split())
    return text if len(text) <= limit else text[:limit] + "..."
