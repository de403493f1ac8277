"""Line lasers: a sheet of light, its plane, and how the rig file describes it.

A line laser's fan of light lies in a plane (Fusiello 13.2.4): a camera pixel lit by it is the
intersection of the pixel's ray with that plane (the ray-plane equation 13.7). The rig file lists the
lasers under ``"lasers"``, each::

    {"name": "laser0",
     "plane": [nx, ny, nz, d],      # the light sheet in the WORLD frame: n . X + d = 0, |n| = 1, metres
     "origin": [x, y, z] | null,    # the emitter, world frame, metres (on the plane); null when unknown
     "fan_angle": 1.05,             # full opening of the fan, radians
     "channel": "red",              # colour the camera sees: red, green, blue or white
     "line_width": 0.0008,          # 1/e^2 full width of the line where it meets the object, metres
     "power": 1.0,                  # relative radiance (1: a white surface at the line's centre reaches
                                    #  full scale through the channel at the default exposure)
     "switch": 1 | null}            # the laser number on the turntable board (Horus M71T<n>, FabScan)

The lasers are fixed to the rig: they do not turn with the table. The normal's sign is free; it is
stored pointing to the side of the plane that holds the camera's centre (:func:`laser_plane`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rangekit.errors import ConfigError

__all__ = ["LineLaser", "LASER_FIELDS", "LASER_CHANNELS", "laser_plane", "laser_from_dict"]

#: The fields of one laser in a rig file, in the order :meth:`LineLaser.to_dict` writes them.
LASER_FIELDS = ("name", "plane", "origin", "fan_angle", "channel", "line_width", "power", "switch")
LASER_CHANNELS = ("red", "green", "blue", "white")


@dataclass(frozen=True, eq=False)
class LineLaser:
    """One line laser. ``plane`` (4,) = (n, d) with n . X + d = 0 in the world frame (metres), |n| = 1;
    ``origin`` (3,) the emitter in the world frame or None; ``fan_angle`` radians; ``line_width`` metres
    (1/e^2 full width); ``power`` relative radiance; ``switch`` the board's laser number or None."""

    plane: np.ndarray
    name: str = "laser"
    origin: np.ndarray | None = None
    fan_angle: float = math.radians(60.0)
    channel: str = "red"
    line_width: float = 0.0008
    power: float = 1.0
    switch: int | None = None

    def __post_init__(self) -> None:
        p = np.asarray(self.plane, dtype=np.float64)
        if p.shape != (4,) or not np.all(np.isfinite(p)) or not np.linalg.norm(p[:3]) > 1e-12:
            raise ConfigError(f"laser {self.name!r}: plane must be 4 finite numbers [nx, ny, nz, d] with a "
                              f"non-zero normal, found {p.tolist() if p.size <= 8 else p.shape}")
        object.__setattr__(self, "plane", p / np.linalg.norm(p[:3]))
        if self.origin is not None:
            o = np.asarray(self.origin, dtype=np.float64)
            if o.shape != (3,) or not np.all(np.isfinite(o)):
                raise ConfigError(f"laser {self.name!r}: origin must be 3 finite numbers (metres) or null, found "
                                  f"{o.tolist() if o.size <= 8 else o.shape}")
            object.__setattr__(self, "origin", o)
        if not (0.0 < float(self.fan_angle) < math.pi):
            raise ConfigError(f"laser {self.name!r}: fan_angle must be in (0, pi) radians, found {self.fan_angle!r}")
        if self.channel not in LASER_CHANNELS:
            raise ConfigError(f"laser {self.name!r}: channel must be one of {', '.join(LASER_CHANNELS)}, found "
                              f"{self.channel!r}")
        for key in ("line_width", "power"):
            value = getattr(self, key)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ConfigError(f"laser {self.name!r}: {key} must be a finite number > 0, found {value!r}")

    @property
    def normal(self) -> np.ndarray:
        """(3,) unit normal of the light sheet, world frame."""
        return self.plane[:3]

    @property
    def offset(self) -> float:
        """d of n . X + d = 0 (metres): the signed distance of the world origin from the plane."""
        return float(self.plane[3])

    def to_dict(self) -> dict:
        return {"name": self.name, "plane": self.plane.tolist(),
                "origin": None if self.origin is None else self.origin.tolist(),
                "fan_angle": float(self.fan_angle), "channel": self.channel, "line_width": float(self.line_width),
                "power": float(self.power), "switch": self.switch}


def laser_plane(normal, point, towards=None) -> np.ndarray:
    """(4,) plane (n, d) through ``point`` with normal ``normal`` (normalised); with ``towards`` (3,) the
    normal points to the side that holds it (e.g. the camera centre)."""
    n = np.asarray(normal, dtype=np.float64)
    n = n / np.linalg.norm(n)
    d = -float(n @ np.asarray(point, dtype=np.float64))
    if towards is not None and n @ np.asarray(towards, dtype=np.float64) + d < 0:
        n, d = -n, -d
    return np.append(n, d)


def laser_from_dict(data, where: str, path: str) -> LineLaser:
    """One entry of a rig file's ``lasers``; errors read ``{where}: {path}.{field}: ...``."""
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: {path}: must be an object with at least 'plane', found {str(data)[:80]!r}")
    unknown = [k for k in data if k not in LASER_FIELDS]
    if unknown:
        raise ConfigError(f"{where}: {path}: unknown field(s) {', '.join(map(repr, unknown))}; a laser has only "
                          f"{', '.join(LASER_FIELDS)}")
    if "plane" not in data:
        raise ConfigError(f"{where}: {path}: missing 'plane' ([nx, ny, nz, d] in the world frame, metres)")
    kwargs = {}
    for key, kind in (("name", str), ("channel", str)):
        if key in data:
            if not isinstance(data[key], kind):
                raise ConfigError(f"{where}: {path}.{key}: must be a string, found {str(data[key])[:80]!r}")
            kwargs[key] = data[key]
    for key in ("fan_angle", "line_width", "power"):
        if key in data:
            v = data[key]
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise ConfigError(f"{where}: {path}.{key}: must be a number, found {str(v)[:80]!r}")
            kwargs[key] = float(v)
    if data.get("switch") is not None:
        s = data["switch"]
        if isinstance(s, bool) or not isinstance(s, int) or not 1 <= s <= 8:
            raise ConfigError(f"{where}: {path}.switch: must be the board's laser number 1..8 or null, found "
                              f"{str(s)[:80]!r}")
        kwargs["switch"] = s
    try:
        plane = np.asarray(data["plane"], dtype=np.float64)
        origin = None if data.get("origin") is None else np.asarray(data["origin"], dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise ConfigError(f"{where}: {path}: plane and origin must be lists of numbers, found "
                          f"{str(data.get('plane'))[:80]!r}, {str(data.get('origin'))[:80]!r}") from None
    try:
        return LineLaser(plane=plane, origin=origin, **kwargs)
    except ConfigError as exc:
        raise ConfigError(f"{where}: {path}: {exc}") from None
