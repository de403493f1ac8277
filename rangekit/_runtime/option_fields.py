"""One place for each option's facts (issue 49): the command-line flag, the range and the default of a field of an
options dataclass (:class:`rangekit.app.scan.options.ScanOptions`, :class:`rangekit.app.process.options.ProcessOptions`)
are the field's metadata, read by the dataclass's check, the command line's parser and the web app's form alike.

    views: int | None = option(None, "--views", lo=2, hi=720, integer=True, initial=12)

``initial`` is the value a new job takes for a field left None (a resumed scan takes its session's instead);
without it the field's own default is the default. Errors name the field as an :class:`~rangekit.errors.OptionError`
``{field}`` template, so the command line shows the flag (:func:`flags`, :meth:`OptionError.named`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

#: ``initial`` not given: a new job takes the field's default.
UNSET = type("Unset", (), {"__repr__": lambda self: "UNSET"})()

__all__ = ["UNSET", "OptionSpec", "option", "specs", "flags", "default_of", "check_ranges", "limits"]


@dataclass(frozen=True)
class OptionSpec:
    """What the metadata of one option says: its ``flag`` on the command line (None: none), its range ``lo..hi``
    (None: unbounded; ``integer``: whole numbers), its ``unit`` (said in a message), and ``initial``: the value of a
    new job when the field is left None (UNSET: the field's default)."""

    flag: str | None = None
    lo: float | None = None
    hi: float | None = None
    integer: bool = False
    unit: str = ""
    initial: object = UNSET
    hi_open: bool = False
    optional: bool = False


def option(default, flag: str | None = None, *, lo=None, hi=None, integer: bool = False, unit: str = "",
           initial=UNSET, hi_open: bool = False, optional: bool | None = None):
    """A dataclass field with ``default`` and its :class:`OptionSpec` as metadata (``hi_open``: values below ``hi``
    only; ``optional``: None is allowed, by default when ``default`` is None)."""
    optional = default is None if optional is None else optional
    return dataclasses.field(default=default, metadata={"option": OptionSpec(flag, lo, hi, integer, unit, initial,
                                                                              hi_open, optional)})


def specs(cls) -> dict[str, OptionSpec]:
    """Every field of the options class ``cls`` (or instance) that has an :class:`OptionSpec`, in order."""
    return {f.name: f.metadata["option"] for f in dataclasses.fields(cls) if "option" in f.metadata}


def flags(cls, prefix: str = "") -> dict[str, str]:
    """``{field: flag}`` of ``cls``'s options that have a flag (``prefix``: the fields named ``PREFIX.field``, as
    a section's fields are in the enclosing options' errors), for :meth:`rangekit.errors.OptionError.named`."""
    return {prefix + name: s.flag for name, s in specs(cls).items() if s.flag is not None}


def default_of(cls, name: str):
    """The value a new job takes for option ``name`` of ``cls``: its ``initial`` when given, else its default."""
    field = {f.name: f for f in dataclasses.fields(cls)}[name]
    spec = field.metadata.get("option")
    if spec is not None and spec.initial is not UNSET:
        return spec.initial
    return field.default


def check_ranges(options, error: type) -> None:
    """Each ranged field of ``options`` (None too when the option is optional) within its range, else ``error`` naming it as
    ``{field}``: ``{views}: expected an integer in 2..720, found 1 (int)``."""
    from rangekit._runtime.arguments import check_number

    for name, s in specs(options).items():
        if s.lo is not None or s.hi is not None:
            check_number(f"{{{name}}}", getattr(options, name), lo=s.lo, hi=s.hi, integer=s.integer, unit=s.unit,
                         hi_open=s.hi_open, optional=s.optional, error=error)


def limits(cls) -> dict[str, dict]:
    """``{field: {"flag", "min", "max", "max_open", "integer", "unit", "default"}}`` of ``cls``'s options that have a
    range: what a form shows and checks (the web app's, ``GET /api/options``)."""
    return {name: {"flag": s.flag, "min": s.lo, "max": s.hi, "max_open": s.hi_open, "integer": s.integer,
                   "unit": s.unit, "default": default_of(cls, name)}
            for name, s in specs(cls).items() if s.lo is not None or s.hi is not None}
