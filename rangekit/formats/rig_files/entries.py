"""The pieces of an imported rig file (:mod:`rangekit.formats.rig_files.importers`): a camera entry, the rig around
it (rigid transforms: rangekit.geometry make_T, invert_T)."""

from __future__ import annotations

import numpy as np

from rangekit.errors import ConfigError
from rangekit.rig.rig_file import template_rig

__all__ = ["camera_entry", "rig_dict"]


def camera_entry(name: str, K, dist, size, T_world_cam, where: str) -> dict:
    """A rig file's camera: K (3, 3) pixels, OpenCV distortion (trailing zeros past 5, 8 or 12 dropped),
    size (w, h), T_world_cam (4, 4) metres."""
    K = np.asarray(K, dtype=np.float64)
    if K.shape != (3, 3) or not np.all(np.isfinite(K)):
        raise ConfigError(f"{where}: expected a finite 3x3 matrix, found shape {K.shape}")
    d = np.asarray(dist, dtype=np.float64).ravel()
    for n in (5, 8, 12):
        if d.size > n and not np.any(d[n:]):
            d = d[:n]
            break
    return {"name": name, "width": int(size[0]), "height": int(size[1]), "K": K.tolist(), "dist": d.tolist(),
            "T_world_cam": np.asarray(T_world_cam, dtype=np.float64).tolist()}


def rig_dict(cameras: list[dict], projector: dict | None, T_world_table, devices: dict, lasers=()) -> dict:
    """The template rig (docs/rig.md) with these devices; capture settings at their defaults."""
    rig = template_rig()
    rig.update(cameras=cameras, projector=projector,
               T_world_table=None if T_world_table is None else np.asarray(T_world_table, float).tolist(),
               devices=devices)
    if lasers:
        rig["lasers"] = list(lasers)
    return rig
