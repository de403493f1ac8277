"""The Scan page's form from the options' own dataclasses (``GET /api/options``): the command line's parsers and
the options' checks read the same metadata (:mod:`rangekit._runtime.option_fields`), so the page, ``rangekit
scan`` and ``rk.scan`` agree on every range and default."""

from __future__ import annotations

__all__ = ["option_limits"]


def option_limits() -> dict:
    """``{"scan": {field: {"flag", "min", "max", "integer", "default", ...}}, "process": {...}}``: each ranged option
    of :class:`~rangekit.app.scan.options.ScanOptions` and :class:`~rangekit.app.process.options.ProcessOptions`,
    and the processing's ``fusion`` and ``mesh_format`` with their ``choices`` and ``default``."""
    from rangekit._runtime.option_fields import default_of, limits
    from rangekit.app.process.fused_outputs import MESH_EXPORT_FORMATS
    from rangekit.app.process.options import FUSION_METHODS, ProcessOptions
    from rangekit.app.scan.options import ScanOptions

    process = limits(ProcessOptions)
    for name, choices in (("fusion", FUSION_METHODS), ("mesh_format", MESH_EXPORT_FORMATS)):
        process[name] = {"choices": list(choices), "default": default_of(ProcessOptions, name)}
    return {"scan": limits(ScanOptions), "process": process}
