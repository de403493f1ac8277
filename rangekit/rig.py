"""The rig file: cameras, projector, turntable axis, and how to reach each device (JSON, versioned).

Schema ``rangekit.rig/1``::

    {
      "schema": "rangekit.rig/1",
      "cameras": [ {camera}, ... ],          # first is the main camera; see PinholeCamera.to_dict
      "projector": {camera} | null,          # a projector is an inverse camera
      "T_world_table": 4x4 | null,           # turntable frame: rotation axis = its z axis, origin on the axis
      "devices": {...},                      # how to reach each device (serial port, baud, protocol, ...)
      "capture": {...}                       # capture settings (exposure, bit depth, ...)
    }

All poses are ``T_world_x`` (maps x's frame to world), metres. A turntable angle theta rotates objects
on the table by ``T_world_table @ Rz(theta) @ inv(T_world_table)``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.errors import ConfigError
from rangekit.geometry import axis_angle_to_R, compose, invert_T, make_T
from rangekit.io import atomic_write_json, read_json

__all__ = ["Rig", "SCHEMA", "load_rig", "save_rig"]

SCHEMA = "rangekit.rig/1"


@dataclass(frozen=True, eq=False)
class Rig:
    """A scanner's geometry and device settings."""

    cameras: tuple[PinholeCamera, ...]
    projector: PinholeCamera | None = None
    T_world_table: np.ndarray | None = None  # (4, 4); table rotation axis = z of this frame
    devices: dict = field(default_factory=dict)
    capture: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not self.cameras:
            raise ConfigError("rig: needs at least one camera in 'cameras'")
        object.__setattr__(self, "cameras", tuple(self.cameras))
        if self.T_world_table is not None:
            T = np.asarray(self.T_world_table, dtype=np.float64)
            if T.shape != (4, 4) or not np.allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-9):
                raise ConfigError(f"rig: 'T_world_table' must be a 4x4 rigid transform, found shape {T.shape}")
            object.__setattr__(self, "T_world_table", T)

    @property
    def camera(self) -> PinholeCamera:
        """The main camera (the first one)."""
        return self.cameras[0]

    def T_world_rotated(self, angle: float) -> np.ndarray:
        """(4, 4) motion of the turntable at ``angle`` radians, in world coordinates."""
        if self.T_world_table is None:
            raise ConfigError("rig: no turntable ('T_world_table' is null), so it cannot rotate")
        Rz = make_T(axis_angle_to_R([0.0, 0.0, 1.0], angle))
        return compose(self.T_world_table, Rz, invert_T(self.T_world_table))

    def to_dict(self) -> dict:
        return {
            "schema": SCHEMA,
            "cameras": [c.to_dict() for c in self.cameras],
            "projector": None if self.projector is None else self.projector.to_dict(),
            "T_world_table": None if self.T_world_table is None else self.T_world_table.tolist(),
            "devices": self.devices,
            "capture": self.capture,
        }

    @classmethod
    def from_dict(cls, data: dict, *, where: str = "rig") -> "Rig":
        if not isinstance(data, dict):
            raise ConfigError(f"{where}: expected a JSON object, found {type(data).__name__}")
        if data.get("schema") != SCHEMA:
            raise ConfigError(f"{where}: field 'schema' must be {SCHEMA!r}, found {data.get('schema')!r}")
        cams = data.get("cameras")
        if not isinstance(cams, list) or not cams:
            raise ConfigError(f"{where}: field 'cameras' must be a non-empty list of cameras")
        cameras = tuple(PinholeCamera.from_dict(c, where=f"{where}: cameras[{i}]") for i, c in enumerate(cams))
        proj = data.get("projector")
        projector = None if proj is None else PinholeCamera.from_dict(proj, where=f"{where}: projector")
        T = data.get("T_world_table")
        if T is not None:
            T = np.asarray(T, dtype=np.float64)
            if T.shape != (4, 4):
                raise ConfigError(f"{where}: field 'T_world_table' must be 4x4, found shape {T.shape}")
        for key in ("devices", "capture"):
            if not isinstance(data.get(key, {}), dict):
                raise ConfigError(f"{where}: field {key!r} must be an object")
        try:
            return cls(cameras=cameras, projector=projector, T_world_table=T,
                       devices=dict(data.get("devices", {})), capture=dict(data.get("capture", {})))
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from exc


def save_rig(rig: Rig, path: str | Path) -> None:
    """Write the rig file atomically."""
    atomic_write_json(path, rig.to_dict())


def load_rig(path: str | Path) -> Rig:
    """Read and validate a rig file; errors name the file and the field."""
    return Rig.from_dict(read_json(path, what="rig file"), where=str(path))
