"""The poses file: for each view its source and ``T_world_view`` (JSON, 4x4 lists, metres).

::

    {"schema": "rangekit.formats.poses/1", "world": "frame of the first view",
     "views": [{"source": "scan0.ply", "T_world_view": [[...], [...], [...], [...]]}, ...]}
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from rangekit.errors import ConfigError
from rangekit.geometry import rigid_problem
from rangekit.io import atomic_write_json, read_json

__all__ = ["save_poses", "load_poses", "POSES_SCHEMA"]

POSES_SCHEMA = "rangekit.formats.poses/1"


def save_poses(path: str | Path, sources: Sequence[str], T_world_view: np.ndarray, *,
               world: str = "frame of the first view", extra: Sequence[dict] | None = None) -> None:
    """Write a poses file atomically; ``extra`` adds per-view fields (e.g. residuals)."""
    T = np.asarray(T_world_view, dtype=np.float64)
    if T.shape != (len(sources), 4, 4):
        raise ConfigError(f"save_poses: {len(sources)} sources but poses of shape {T.shape}")
    views = [{"source": str(s), "T_world_view": T[k].tolist(), **((extra or [{}] * len(sources))[k])}
             for k, s in enumerate(sources)]
    atomic_write_json(path, {"schema": POSES_SCHEMA, "world": world, "views": views})


def load_poses(path: str | Path) -> tuple[list[str], np.ndarray]:
    """(sources, (n, 4, 4) T_world_view) from a poses file; errors name the file and the view."""
    data = read_json(path, what="poses file")
    views = data.get("views") if isinstance(data, dict) else None
    if not isinstance(views, list) or not views:
        raise ConfigError(f"{path}: expected {{'views': [{{'source': ..., 'T_world_view': 4x4}}, ...]}}")
    sources, Ts = [], []
    for k, v in enumerate(views):
        try:
            T = np.asarray(v["T_world_view"], dtype=np.float64)
        except (KeyError, TypeError, ValueError) as exc:
            raise ConfigError(f"{path}: views[{k}] needs a numeric 'T_world_view' 4x4 list") from exc
        problem = rigid_problem(T, tol=1e-6)  # a poses file may be written with fewer digits
        if problem is not None:
            raise ConfigError(f"{path}: views[{k}].T_world_view must be a 4x4 rigid transform (finite, rotation "
                              f"with determinant +1, last row 0 0 0 1), found {problem}")
        source = v.get("source", f"view{k}") if isinstance(v, dict) else None
        if not isinstance(source, str):
            raise ConfigError(f"{path}: views[{k}].source must be a file name, found {source!r:.80}")
        sources.append(source)
        Ts.append(T)
    return sources, np.stack(Ts)
