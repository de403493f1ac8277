"""Is a length plausible for a scanner, and if not, in which unit do its numbers look right?

A file in millimetres read as metres (or the other way round) loads without a complaint and scales every
result by 1000. These rules catch it at the boundary, where a length is read: a baseline far outside what a
desk-top scanner can have, or an object mesh the size of a building, is refused (:class:`ConfigError` for a
rig or calibration file, the caller's error class elsewhere), naming the value and the unit its numbers look
like; one merely unusual is a warning on the ``rangekit`` logger. The one source of each fact:

- :data:`BASELINE`: a camera-projector or stereo baseline is plausible from 5 mm to 2 m, refused below 1 mm
  or above 10 m, and refused when zero;
- :data:`OBJECT_SIZE`: a simulated object's bounding-box diagonal is plausible from 5 mm to 2 m (the
  simulated rig's measuring volume is a few tens of centimetres), refused below 1 mm or above 5 m;
- :data:`UNIT_SCALES`: the units a length in a file may be in, metres per unit;
- :data:`FOCAL_PER_WIDTH`, :data:`PRINCIPAL_SPAN`, :data:`MIN_IMAGE_SIDE_PX`: a camera's or projector's
  intrinsics (:func:`intrinsics_problem`), the one rule of every rig file, import and preset: a focal length
  from a 170-degree fisheye's (0.05 image widths) to a 0.6-degree telephoto's (100 widths), fx and fy within
  5x of each other, the principal point within one image size beyond the image (projectors' offset optics put
  it near or past an edge), an image of at least 8 pixels a side.

:func:`check_length` applies a rule; :func:`check_stereo_baseline` is the check of a stereo rig file.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Iterable, Mapping

import numpy as np

from rangekit.errors import ConfigError, InputError

__all__ = ["FOCAL_PER_WIDTH", "MIN_IMAGE_SIDE_PX", "PRINCIPAL_SPAN", "intrinsics_problem", "LengthRule", "BASELINE", "OBJECT_SIZE", "OBJECT_UNITS", "UNIT_SCALES", "UNIT_NAMES", "check_length",
           "likely_unit", "format_length", "format_vector", "check_stereo_baseline"]

#: Metres per unit of the lengths a file may hold; the order is the order units are guessed in.
UNIT_SCALES = {"mm": 1e-3, "m": 1.0, "cm": 1e-2}
UNIT_NAMES = {"mm": "millimetres", "m": "metres", "cm": "centimetres"}
#: The units an object mesh file may be given in (``sim render --object-unit``).
OBJECT_UNITS = ("m", "mm")


#: A focal length's plausible range in image widths (module doc).
FOCAL_PER_WIDTH = (0.05, 100.0)
#: How far the principal point may lie from the image, in image sizes on either side.
PRINCIPAL_SPAN = 1.0
#: The smallest image side a camera or projector can have, pixels.
MIN_IMAGE_SIDE_PX = 8


def intrinsics_problem(K: np.ndarray, width: int, height: int) -> str | None:
    """What is implausible about a pinhole's ``K`` (3, 3) for a ``width`` x ``height`` image (pixels), in words
    naming the value and the range; None when nothing is."""
    if min(width, height) < MIN_IMAGE_SIDE_PX:
        return f"an image of {width}x{height} pixels is smaller than {MIN_IMAGE_SIDE_PX} pixels a side"
    lo, hi = FOCAL_PER_WIDTH
    for name, f in (("fx", K[0, 0]), ("fy", K[1, 1])):
        if not lo * width <= f <= hi * width:
            return (f"{name} = {f:.6g} px is not a lens's focal length for a {width}-pixel-wide image (expected "
                    f"{lo * width:g} to {hi * width:g} px)")
    if not 0.2 <= K[0, 0] / K[1, 1] <= 5.0:
        return f"fx / fy = {K[0, 0] / K[1, 1]:.4g}: pixels that much wider than high are no camera's (expected 0.2 to 5)"
    for name, c, size in (("cx", K[0, 2], width), ("cy", K[1, 2], height)):
        if not -PRINCIPAL_SPAN * size <= c <= (1 + PRINCIPAL_SPAN) * size:
            return (f"{name} = {c:.6g} px lies more than an image size outside a {size}-pixel image (expected "
                    f"{-PRINCIPAL_SPAN * size:g} to {(1 + PRINCIPAL_SPAN) * size:g} px)")
    return None


@dataclass(frozen=True)
class LengthRule:
    """A kind of length (``name``, e.g. "camera-projector baseline") with its ``plausible`` range and the
    ``limits`` outside which it is refused, metres (low, high)."""

    name: str
    plausible: tuple[float, float]
    limits: tuple[float, float]

    def verdict(self, length: float) -> str:
        """The verdict on ``length`` (metres): "refuse" (zero, not finite, or outside ``limits``), "warn"
        (outside ``plausible``) or "ok"."""
        if not (math.isfinite(length) and length > 0) or not self.limits[0] <= length <= self.limits[1]:
            return "refuse"
        return "ok" if self.plausible[0] <= length <= self.plausible[1] else "warn"

    def expected(self) -> str:
        lo, hi = self.plausible
        return f"{format_length(lo)} to {format_length(hi)}"


#: A camera-projector or stereo baseline (distance between the optical centres).
BASELINE = LengthRule("baseline", plausible=(0.005, 2.0), limits=(0.001, 10.0))
#: A simulated object's size: its bounding-box diagonal.
OBJECT_SIZE = LengthRule("object", plausible=(0.005, 2.0), limits=(0.001, 5.0))
#: A calibration board's square side (``--square-mm``): printed boards from a 2 mm grid to a 200 mm poster;
#: below 0.5 mm no camera resolves it, above 0.5 m it is no board a camera sees whole.
BOARD_SQUARE = LengthRule("board square", plausible=(0.002, 0.2), limits=(0.0005, 0.5))


def format_length(length: float) -> str:
    """A length in metres as a person writes it: ``200 m``, ``75 mm``, ``0.2 mm``."""
    if not math.isfinite(length):
        return f"{length} m"
    if length == 0:
        return "0 m"
    return f"{length:.3g} m" if abs(length) >= 1.0 else f"{length * 1e3:.3g} mm"


def format_vector(values) -> str:
    """``(200, 0, 0)``: numbers as the file wrote them (4 significant digits); at most 8 of them, then how many
    there were (an error quotes it: rangekit.errors.shown)."""
    flat = np.asarray(values, dtype=np.float64).ravel()
    more = f", ... ({flat.size} numbers)" if flat.size > 8 else ""
    return "(" + ", ".join(f"{float(v):.4g}" for v in flat[:8]) + more + ")"


def likely_unit(length: float, rule: LengthRule, read_as: str = "m", units: Iterable[str] | None = None) -> str | None:
    """The unit (one of ``units``, default every key of :data:`UNIT_SCALES`, other than ``read_as``) in which
    the numbers of ``length`` (metres, read as ``read_as``) give a plausible ``rule`` length; None if no unit
    does (or it is zero)."""
    if not (math.isfinite(length) and length > 0):
        return None
    numbers = length / UNIT_SCALES[read_as]
    for unit, scale in UNIT_SCALES.items():
        if unit != read_as and (units is None or unit in units) \
                and rule.plausible[0] <= numbers * scale <= rule.plausible[1]:
            return unit
    return None


def check_length(length: float, rule: LengthRule, *, where: str, shown: str, what: str | None = None,
                 read_as: str = "m", units: Iterable[str] | None = None, source: str = "the file",
                 fixes: Mapping[str, str] | None = None, error: type[InputError] = ConfigError) -> str:
    """Refuse ``length`` (metres; ``rule``'s verdict "refuse": raise ``error``) or warn of it ("warn": log a
    warning on the ``rangekit`` logger); returns the verdict.

    The message reads ``{where}: {shown}: a {length} {what}; {source} looks like {unit}: {fix}``, where
    ``shown`` is the value as read (``T = (200, 0, 0) m``), ``what`` the length's name (default
    ``rule.name``), ``unit`` the one its numbers look right in (:func:`likely_unit`) and ``fix``
    ``fixes[unit]`` (how to read the file in that unit), when given; without a likely unit, the plausible range.
    ``units``: the units guessed (default every one of :data:`UNIT_SCALES`; those the caller can read).
    """
    verdict = rule.verdict(length)
    if verdict == "ok":
        return verdict
    what = what or rule.name
    size = f"a zero {what}" if length == 0 else f"a {format_length(length)} {what}"
    unit = likely_unit(length, rule, read_as, units)
    hints = [] if verdict == "warn" and unit is None else [
        f"{source} looks like {UNIT_NAMES[unit]}" + (f": {fixes[unit]}" if fixes and unit in fixes else "")
        if unit is not None else f"expected {rule.expected()}"]
    if verdict == "refuse":
        raise error("; ".join([f"{where}: {shown}: {size}", *hints]))
    from rangekit.progress import LOGGER

    LOGGER.warning("; ".join([f"{where}: {shown}: {size}, outside the usual {rule.expected()}", *hints]))
    return verdict


def check_stereo_baseline(rig, where: str) -> float:
    """The baseline (metres) of a stereo rig file's ``cameras[0]`` (left) and ``cameras[1]`` (right), checked
    by :data:`BASELINE`: a rig file in millimetres (a 75 m baseline, every depth 1000 times too far) or with
    the two cameras at one point is refused."""
    left, right = rig.cameras[0], rig.cameras[1]
    offset = np.asarray(right.T_world_cam, dtype=np.float64)[:3, 3] - np.asarray(left.T_world_cam)[:3, 3]
    length = float(np.linalg.norm(offset))
    check_length(length, BASELINE, where=where, read_as="m", units=("mm",), source="the rig file",
                 what="stereo baseline",
                 shown=f"cameras[1] ({right.name!r}) is {format_vector(offset)} m from cameras[0] ({left.name!r})",
                 fixes={"mm": "divide every T_world_cam translation by 1000 (rig files are in metres)"})
    return length
