"""A camera's exposure, gain, white balance and focus, as the rig file's ``capture.camera`` gives them.

Coded light compares every pixel across 20-60 frames against thresholds set by its own white and black
frames: the camera must not change its exposure, gain or white balance between frames, and its focus
must stay where it was calibrated. So for coded light every control is *locked* by default (manual
exposure and gain, manual white balance, fixed lens position); auto-exposure is refused unless the rig
file says ``"allow_auto_exposure": true``.

``capture.camera`` fields (all optional; docs/rig.md)::

    "exposure_us": 1..1000000 | "auto"       # exposure time, microseconds (default 33333)
    "iso": 100..1600 | "auto"                # sensor gain as ISO (default 100)
    "white_balance_k": 1000..12000 | "auto" | "mono"   # colour temperature, K (default 5600)
    "focus": 0..255 | "auto"                 # lens position (depthai's 0..255; default 130)
    "lock_focus": true | false               # keep the lens where it is (default true)
    "fps": 0.1..120                          # frame rate (default 30)
    "allow_auto_exposure": true | false      # coded light with "exposure_us": "auto" (default false)

With a DLP projector, ``devices.projector.refresh_hz`` (its refresh rate, Hz) makes the exposure a whole
number of refresh periods: a DLP shows grey levels as a sequence of mirror flips (and colours as a wheel)
within each period, and a camera exposing a fraction of one captures a band of it.
:func:`check_refresh` refuses an exposure more than 1% of a period off a whole number of periods.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

from rangekit.errors import ConfigError, shown

__all__ = ["CameraControls", "CONTROL_FIELDS", "controls_from_capture", "check_refresh", "require_locked",
           "round_to_refresh"]

#: The fields of ``capture.camera`` and their ranges: name -> (smallest, largest, unit, words allowed).
CONTROL_FIELDS = {
    "exposure_us": (1.0, 1_000_000.0, "microseconds", ("auto",)),
    "iso": (100, 1600, "ISO", ("auto",)),
    "white_balance_k": (1000, 12000, "kelvin", ("auto", "mono")),
    "focus": (0, 255, "lens position", ("auto",)),
    "fps": (0.1, 120.0, "frames per second", ()),
}
_FLAGS = ("lock_focus", "allow_auto_exposure")


@dataclass(frozen=True)
class CameraControls:
    """Camera settings; ``None`` means the camera's automatic control."""

    exposure_us: float | None = 33_333.0
    iso: int | None = 100
    white_balance_k: int | None = 5600
    mono: bool = False
    focus: int | None = 130
    lock_focus: bool = True
    fps: float = 30.0
    allow_auto_exposure: bool = False

    @property
    def auto_exposure(self) -> bool:
        return self.exposure_us is None

    def to_dict(self) -> dict:
        """The ``capture.camera`` object that :func:`controls_from_capture` reads back."""
        d = asdict(self)
        out = {"exposure_us": "auto" if d["exposure_us"] is None else d["exposure_us"],
               "iso": "auto" if d["iso"] is None else d["iso"],
               "white_balance_k": "mono" if d["mono"] else ("auto" if d["white_balance_k"] is None
                                                            else d["white_balance_k"]),
               "focus": "auto" if d["focus"] is None else d["focus"]}
        return {**out, "lock_focus": self.lock_focus, "fps": self.fps, "allow_auto_exposure": self.allow_auto_exposure}


def _number(value, name: str, where: str):
    lo, hi, unit, words = CONTROL_FIELDS[name]
    if isinstance(value, str) and value in words:
        return value
    integer = isinstance(lo, int)
    ok = (isinstance(value, int) if integer else isinstance(value, (int, float))) and not isinstance(value, bool)
    if not ok or not (lo <= value <= hi):
        choices = "".join(f" or {w!r}" for w in words)
        raise ConfigError(f"{where}: capture.camera.{name}: expected {'an integer' if integer else 'a number'} "
                          f"{lo}..{hi} ({unit}){choices}, found {shown(value)}")
    return value


def controls_from_capture(capture: dict | None, *, where: str) -> CameraControls:
    """The :class:`CameraControls` of a rig file's ``capture`` section (its ``camera`` object; defaults
    where absent). Raises ConfigError naming ``where`` (the rig file) and the field."""
    cam = (capture or {}).get("camera", {})
    if not isinstance(cam, dict):
        raise ConfigError(f"{where}: capture.camera: expected an object {{...}}, found {shown(cam)}")
    unknown = sorted(set(cam) - set(CONTROL_FIELDS) - set(_FLAGS))
    if unknown:
        raise ConfigError(f"{where}: capture.camera.{unknown[0]}: unknown field; capture.camera has only "
                          f"{', '.join([*CONTROL_FIELDS, *_FLAGS])}")
    for flag in _FLAGS:
        if flag in cam and not isinstance(cam[flag], bool):
            raise ConfigError(f"{where}: capture.camera.{flag}: expected true or false, found {shown(cam[flag])}")
    d = CameraControls()
    v = {k: _number(cam[k], k, where) for k in CONTROL_FIELDS if k in cam}
    wb = v.get("white_balance_k", d.white_balance_k)
    return CameraControls(
        exposure_us=None if v.get("exposure_us") == "auto" else float(v.get("exposure_us", d.exposure_us)),
        iso=None if v.get("iso") == "auto" else int(v.get("iso", d.iso)),
        white_balance_k=None if wb in ("auto", "mono") else int(wb), mono=wb == "mono",
        focus=None if v.get("focus") == "auto" else int(v.get("focus", d.focus)),
        lock_focus=cam.get("lock_focus", d.lock_focus), fps=float(v.get("fps", d.fps)),
        allow_auto_exposure=cam.get("allow_auto_exposure", d.allow_auto_exposure))


def check_refresh(controls: CameraControls, refresh_hz: float | None, *, where: str) -> None:
    """Refuse a manual exposure that is not a whole number of the projector's refresh periods (within 1%
    of a period); nothing to check with auto-exposure or no ``refresh_hz``."""
    if refresh_hz is None or controls.exposure_us is None:
        return
    period_us = 1e6 / float(refresh_hz)
    n = controls.exposure_us / period_us
    if n < 1 - 0.01 or abs(n - round(n)) > 0.01:
        k = max(1, round(n))
        raise ConfigError(f"{where}: capture.camera.exposure_us: expected a whole number of the projector's "
                          f"refresh periods ({period_us:.1f} us at devices.projector.refresh_hz {refresh_hz:g}), "
                          f"found {controls.exposure_us:g} us = {n:.3f} periods; use {k * period_us:.0f} or "
                          f"{(k + 1) * period_us:.0f}")


def round_to_refresh(exposure_us: float, refresh_hz: float | None) -> float:
    """``exposure_us`` rounded to the nearest whole number (at least 1) of the projector's refresh periods
    (microseconds; unchanged without ``refresh_hz``), so that :func:`check_refresh` accepts it."""
    if refresh_hz is None:
        return float(exposure_us)
    period_us = 1e6 / float(refresh_hz)
    return float(max(1, round(float(exposure_us) / period_us)) * period_us)


def require_locked(controls: CameraControls, *, where: str, method: str = "coded light") -> None:
    """Refuse auto-exposure for ``method`` unless ``allow_auto_exposure`` is set."""
    if controls.auto_exposure and not controls.allow_auto_exposure:
        raise ConfigError(f"{where}: capture.camera.exposure_us: {method} needs a locked exposure (a number of "
                          "microseconds), found 'auto': auto-exposure changes the brightness between the white, "
                          "black and pattern frames and breaks decoding; set a value (rangekit check suggests "
                          "one) or \"allow_auto_exposure\": true")
