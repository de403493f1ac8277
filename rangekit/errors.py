"""The rangekit exception hierarchy.

Every error a user can cause (a bad file, a bad argument, a device that does not answer) is raised as
one of these, with a message that names the input, what was expected and what was found. The CLI
catches :class:`RangekitError`, prints ``rangekit: error: MESSAGE`` and exits 2 for a
:class:`UsageError` (a bad option), 1 for anything else, without a traceback.
"""

__all__ = [
    "RangekitError",
    "InputError",
    "UsageError",
    "BudgetError",
    "BudgetUsageError",
    "FileFormatError",
    "SceneError",
    "PatternError",
    "ConfigError",
    "DecodeError",
    "CalibrationError",
    "RegistrationError",
    "MeshError",
    "DeviceError",
    "DeviceTimeout",
    "DeviceDisconnected",
    "ProtocolError",
    "CommandError",
]


class RangekitError(Exception):
    """Base of every error rangekit raises on purpose."""


class InputError(RangekitError, ValueError):
    """An argument has the wrong shape, type or value."""


class UsageError(InputError):
    """A command-line option has a bad value or names an output that cannot be written (the CLI exits 2;
    every other :class:`RangekitError` is a runtime failure and exits 1)."""


class BudgetError(InputError):
    """An input (a file's header, a spec's sizes) asks for more memory or work than rangekit allows: the
    memory budget of :mod:`rangekit.budget`, or a documented size limit. Raised before allocating."""


class BudgetUsageError(UsageError, BudgetError):
    """A command-line option asks for more memory than the budget allows (the CLI exits 2)."""


class FileFormatError(InputError):
    """A file is missing, unreadable, or not of the expected format."""


class SceneError(InputError):
    """A simulated scene cannot be built or seen (empty mesh, camera that sees nothing)."""


class PatternError(InputError):
    """A pattern image or pattern spec does not fit the projector or the capture."""


class ConfigError(InputError):
    """A rig file or settings file has a missing or invalid field."""


class DecodeError(RangekitError):
    """A capture stack cannot be decoded into projector coordinates."""


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


class ProtocolError(DeviceError):
    """A device answered something the protocol does not allow."""


class CommandError(DeviceError):
    """A device understood a command and refused it."""
