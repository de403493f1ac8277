"""A processed session's carved space made again from what processing left on disk: each view's cache
(``cloud.ply``, ``maps.npz``) and the registered poses (``poses.json``), through the very functions
``rangekit process`` makes it with (:func:`rangekit.app.process.decode.decode`'s free depths,
:func:`rangekit.app.process.fuse.carved_space`). For checks and benchmarks of the closed mesh that do not take the
processing's word for it (tests/app/process/test_carved_closing.py, benchmarks/surface/closed_breakdown.py).
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from rangekit.app.process.decode import decode
from rangekit.app.process.fuse import carved_space
from rangekit.app.process.options import ProcessOptions
from rangekit.app.process.register import RegisteredViews
from rangekit.app.process.view_cache import ViewCaches
from rangekit.errors import InputError
from rangekit.formats.poses import load_poses
from rangekit.formats.sessions.files import POSES_FILE
from rangekit.formats.sessions.session import Session
from rangekit.surface.mesh import TriangleMesh

__all__ = ["carved_space_of"]


def carved_space_of(session: Session | str | Path, mesh: TriangleMesh, options: ProcessOptions | None = None):
    """The carved space (:class:`rangekit.surface.carve.CarvedSpace`, session world) of the processed
    ``session`` (a :class:`Session` or its folder) on the grid around ``mesh`` (its observed mesh, e.g.
    ``mesh.ply`` read back) as :func:`rangekit.app.process.fuse.carved_space` makes it: each completed view's free
    depth from its cached maps (a cache not made with ``options``' settings, default :class:`ProcessOptions`, is
    decoded again from the frames; every frame's SHA-256 is checked), seen from its pose in ``poses.json``. None
    where processing carves nothing (no turntable)."""
    if not isinstance(session, Session):
        session = Session.load(Path(session))
    options = replace(options or ProcessOptions(), report=False)
    done = session.done_views
    _, T_world_view = load_poses(session.folder / POSES_FILE)
    if len(T_world_view) != len(done):
        raise InputError(f"carved_space_of: {session.folder / POSES_FILE} holds {len(T_world_view)} poses, "
                         f"expected one per completed view ({len(done)})")
    caches = ViewCaches(session.folder, [v.index for v in done], options.method, options.table_margin,
                        options.max_motion)
    decoded = decode(session, options, (caches.pop(v.index) for v in done))
    registered = RegisteredViews(decoded, T_world_view, edges=[], rmse=float("nan"), view_passes=None)
    return carved_space(registered, mesh, session.rig)
