"""A decoded view's points for the Scan page's 3D view: read from the view's cloud cache (``view_*/cloud.ply``,
written as the view is decoded), placed by the turntable's prior, thinned to :data:`POINTS_PER_VIEW`; fetched when
the page's events say the view was decoded (:class:`rangekit.app.events.ViewDecoded`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from rangekit.errors import RangekitError
from rangekit.formats.sessions.files import CLOUD_FILE, CLOUD_INFO_FILE

__all__ = ["POINTS_PER_VIEW", "view_points"]

#: The most points of one view sent to a page (every n-th of the view's cloud).
POINTS_PER_VIEW = 20_000


def view_points(folder: Path, index: int) -> bytes:
    """Float32 (n, 3) bytes, x y z in millimetres, of view ``index``'s decoded cloud placed by the turntable prior
    (the first view's frame), every k-th point so that n <= :data:`POINTS_PER_VIEW`."""
    from rangekit.formats.clouds import load_cloud
    from rangekit.formats.sessions.session import Session
    from rangekit.geometry import apply_T
    from rangekit.rig.rig_file import turntable_prior

    session = Session.load(folder)
    if not 0 <= index < len(session.views):
        raise RangekitError(f"view {index}: the session has views 0-{len(session.views) - 1}")
    view = session.views[index]
    if not (view.folder / CLOUD_INFO_FILE).is_file():
        raise RangekitError(f"{view.folder.name}: not decoded yet")
    cloud = load_cloud(view.folder / CLOUD_FILE)
    step = max(1, -(-len(cloud) // POINTS_PER_VIEW))
    points = cloud.points[::step]
    rig = session.rig
    if rig.T_world_table is not None:
        T = turntable_prior(rig.T_world_table, [session.views[0].angle, view.angle])[1]
        points = apply_T(T, points)
    return (np.asarray(points, dtype=np.float32) * 1e3).tobytes()
