"""The memory budget: how much memory one input may make rangekit allocate, checked *before* allocating.

The budget in bytes is, in order:

1. the environment variable ``RANGEKIT_MEMORY_BUDGET`` when set: bytes, or a number with a unit
   ``K``, ``M``, ``G``, ``T`` (powers of 1024; ``8G``, ``512MiB``, ``1.5g`` and ``2000000000`` all work);
2. else half the machine's physical memory, or half the cgroup memory limit when that is lower (a
   container: ``memory.max`` of cgroup v2, ``memory.limit_in_bytes`` of cgroup v1).

Checked against it, each from sizes known before any pixel is read or allocated: an image stack from
its files' headers (:func:`rangekit.image_header.check_image_files`: a capture folder, a ToF sample
folder, a stereo pair, a DiLiGenT object), a rendered or simulated image from its size, a pattern frame
from its spec, a calibration board's texture. :func:`check_budget` raises :class:`BudgetError` (exit 1)
or, for a command-line option, :class:`BudgetUsageError` (exit 2), naming what, the need and the budget.

:data:`MAX_IMAGE_SIDE_PX` bounds one side of any image rangekit renders or any camera or projector it
models (command-line sizes, rig files, pattern specs), whatever the budget.
"""

from __future__ import annotations

import math
import os
import re
from pathlib import Path

from rangekit.errors import BudgetError, BudgetUsageError, UsageError

__all__ = ["ENV_VAR", "MAX_IMAGE_SIDE_PX", "memory_budget", "budget_source", "physical_memory",
           "cgroup_memory_limit", "parse_bytes", "format_bytes", "array_bytes", "check_budget"]

#: The environment variable that overrides the budget (bytes, or with a unit K/M/G/T).
ENV_VAR = "RANGEKIT_MEMORY_BUDGET"
#: The largest side, in pixels, of an image rangekit renders, a camera or a projector it models.
MAX_IMAGE_SIDE_PX = 16384

_UNITS = {"": 1, "k": 2**10, "m": 2**20, "g": 2**30, "t": 2**40}
_BYTES = re.compile(r"^\s*(\d+(?:\.\d*)?(?:e[+-]?\d+)?)\s*([kmgt]?)(?:i?b)?\s*$", re.IGNORECASE)
_UNLIMITED = 2**60  # cgroup v1 writes about 2**63 for "no limit"


def parse_bytes(text: str) -> int:
    """``"8G"`` -> 8 * 2**30: a byte count with an optional unit K, M, G, T (powers of 1024, optional
    ``B``/``iB``). Raises UsageError naming :data:`ENV_VAR` for anything else or a count < 1."""
    m = _BYTES.match(str(text))
    value = float(m.group(1)) * _UNITS[m.group(2).lower()] if m else math.nan
    if not (math.isfinite(value) and value >= 1):
        raise UsageError(f"{ENV_VAR}={text!r}: expected a memory size in bytes >= 1, optionally with a unit "
                         "K, M, G or T (powers of 1024), e.g. 8G")
    return int(value)


def format_bytes(n: float) -> str:
    """``1536`` -> ``"1.5 KiB"``: a byte count for messages."""
    n = float(n)
    for unit in ("B", "KiB", "MiB", "GiB", "TiB"):
        if abs(n) < 1024 or unit == "TiB":
            return f"{n:.0f} B" if unit == "B" else f"{n:.3g} {unit}"
        n /= 1024
    return f"{n:.3g} TiB"  # pragma: no cover


def physical_memory() -> int:
    """Bytes of physical memory (``sysconf``); 8 GiB where the system does not say."""
    try:
        return int(os.sysconf("SC_PAGE_SIZE")) * int(os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return 8 * 2**30


def cgroup_memory_limit(root: str | Path = "/sys/fs/cgroup", proc: str | Path = "/proc/self/cgroup") -> int | None:
    """The lowest memory limit of this process's cgroup (v2 ``memory.max`` or v1 ``memory.limit_in_bytes``, of
    its own group and of the mount root), in bytes; None when there is none or it cannot be read."""
    root = Path(root)
    groups = [""]
    try:
        for line in Path(proc).read_text().splitlines():
            _, controllers, path = line.split(":", 2)
            if controllers in ("", "memory") or "memory" in controllers.split(","):
                groups.append(path.strip("/"))
    except (OSError, ValueError):
        pass
    limits = []
    for group in groups:
        for name in (f"{group}/memory.max", f"memory/{group}/memory.limit_in_bytes"):
            try:
                text = (root / name.lstrip("/")).read_text().strip()
            except OSError:
                continue
            if text.isdigit() and 0 < int(text) < _UNLIMITED:
                limits.append(int(text))
    return min(limits) if limits else None


def budget_source() -> str:
    """Where :func:`memory_budget` comes from, for messages."""
    if os.environ.get(ENV_VAR, "").strip():
        return f"set by {ENV_VAR}"
    limit = cgroup_memory_limit()
    if limit is not None and limit < physical_memory():
        return f"half the cgroup memory limit of {format_bytes(limit)}"
    return f"half the {format_bytes(physical_memory())} of physical memory"


def memory_budget() -> int:
    """The budget in bytes (see the module docstring); read afresh on every call."""
    text = os.environ.get(ENV_VAR, "").strip()
    if text:
        return parse_bytes(text)
    limit = cgroup_memory_limit()
    total = physical_memory() if limit is None else min(limit, physical_memory())
    return total // 2


def array_bytes(shape, itemsize: int) -> int:
    """Bytes of an array of ``shape`` with ``itemsize``-byte elements, in exact integers (no overflow)."""
    return math.prod(int(s) for s in shape) * int(itemsize)


def check_budget(n_bytes: int, what: str, *, option: str | None = None) -> None:
    """Raise unless ``n_bytes`` fit the budget: :class:`BudgetError` naming ``what``, the bytes needed and the
    budget, or :class:`BudgetUsageError` (a usage error, exit 2) starting with ``option`` when one is given."""
    allowed = memory_budget()
    if n_bytes <= allowed:
        return
    msg = (f"{what} needs {format_bytes(n_bytes)} of memory, more than the memory budget of "
           f"{format_bytes(allowed)} ({budget_source()}); set {ENV_VAR} (bytes, or e.g. 16G) to allow more")
    if option is not None:
        raise BudgetUsageError(f"{option}: {msg}")
    raise BudgetError(msg)
