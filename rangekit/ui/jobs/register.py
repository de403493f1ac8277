"""The Registration page's job: clouds picked from the sessions folder registered into one frame, as ``rangekit
register`` does (:func:`rangekit.app.commands.register.register`), on a thread; each pair's residual shown, then
saved under a name.

A run writes into a staging folder (:data:`STAGING`, hidden in the sessions folder: poses.json and merged.ply);
*save* moves it to ``sessions/NAME`` (refused when NAME exists), so nothing lands under a name before the
person has looked at the residuals.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np

from rangekit.errors import RangekitError
from rangekit.ui.jobs.base import Job, JobState
from rangekit.ui.jobs.notifier import Topic
from rangekit.ui.paths import confined
from rangekit.ui.sessions_list import readable_name
from rangekit.formats.sessions.files import MESH_FILE, PREVIEW_FILE, WATERTIGHT_FILE

__all__ = ["CLOUD_SUFFIXES", "RegisterJob", "list_clouds"]

#: The cloud files the page offers (what :func:`rangekit.formats.clouds.load_cloud` reads).
CLOUD_SUFFIXES = (".ply", ".pcd", ".xyz", ".npy", ".e57")
STAGING = ".registering"
#: The most files listed, and the most points of one cloud sent to a page.
MAX_LISTED, POINTS_PER_CLOUD = 2000, 20_000
_NOT_CLOUDS = {MESH_FILE, WATERTIGHT_FILE, PREVIEW_FILE}   # meshes, not scans


def list_clouds(sessions: Path) -> list[str]:
    """The cloud files under ``sessions`` (relative POSIX paths, sorted; meshes, frames and the staging folder
    left out, and any whose path is not UTF-8: a page could not name it back), at most :data:`MAX_LISTED`."""
    root = Path(sessions).resolve()
    out = []
    for dirpath, dirnames, filenames in os.walk(root):
        dirnames[:] = sorted(d for d in dirnames if not d.startswith(".") and d != "frames")
        for name in sorted(filenames):
            if Path(name).suffix.lower() in CLOUD_SUFFIXES and name not in _NOT_CLOUDS:
                path = Path(dirpath) / name
                if path.resolve().is_relative_to(root) and readable_name(str(path)) is not None:
                    out.append(path.relative_to(root).as_posix())
                    if len(out) >= MAX_LISTED:
                        return out
    return out


class RegisterJob(Job):
    """The latest registration of clouds under ``sessions``."""

    WHAT, SHOWN_LINES, TOPIC = "registration", 30, Topic.REGISTER

    def __init__(self, sessions: Path, notifier=None) -> None:
        super().__init__(notifier)
        self.sessions = Path(sessions).resolve()
        self._report = None

    def start(self, files: list, neighbours=None) -> dict:
        """Register ``files`` (paths relative to the sessions folder, 2 or more) on a thread."""
        if not isinstance(files, list) or len(files) < 2:
            raise RangekitError(f"clouds: pick at least 2 clouds to register, found {len(files) if isinstance(files, list) else files!r}")
        paths = [confined(self.sessions, f) for f in files]
        for f, p in zip(files, paths):
            if not p.is_file():
                raise RangekitError(f"clouds: {f}: no such file under the sessions folder")
        if neighbours is not None and (isinstance(neighbours, bool) or not isinstance(neighbours, int) or neighbours < 0):
            raise RangekitError(f"neighbours: expected a whole number >= 0 (0: every pair), found {neighbours!r}")
        self.begin(files=list(files))
        self._report = None
        self.launch(self._run, paths, list(files), neighbours, keep={"files": list(files)})
        return self.snapshot()

    def _run(self, paths: list[Path], files: list[str], neighbours) -> dict:
        from rangekit.app.commands.register import register

        staging = self.sessions / STAGING
        shutil.rmtree(staging, ignore_errors=True)
        report = register(paths, staging, mesh=False, progress=self.say, neighbours=neighbours)
        res = report.result
        pairs = [{"i": e.i, "j": e.j, "a": files[e.i], "b": files[e.j], "rmse_mm": round(e.rmse * 1e3, 4),
                  "overlap_percent": round(100 * e.overlap, 1), "accepted": bool(e.accepted), "reason": e.reason}
                 for e in res.edges]
        with self._cond:
            self._report = report
        return {"pairs": pairs, "rmse_mm": round(res.rmse * 1e3, 4), "converged": bool(res.converged)}

    def points(self, k: int) -> bytes:
        """Float32 (n, 3) bytes, millimetres in the first cloud's frame: cloud ``k`` of the last registration,
        placed by its registered pose, every m-th point so that n <= :data:`POINTS_PER_CLOUD`."""
        from rangekit.formats.clouds import load_cloud
        from rangekit.geometry import apply_T

        with self._cond:
            report = self._report
        if report is None:
            raise RangekitError("no finished registration: register the clouds first")
        if not 0 <= k < len(report.sources):
            raise RangekitError(f"cloud {k}: the registration has clouds 0-{len(report.sources) - 1}")
        cloud = load_cloud(report.sources[k])
        step = max(1, -(-len(cloud) // POINTS_PER_CLOUD))
        pts = apply_T(report.result.T_world_view[k], np.asarray(cloud.points)[::step])
        return (pts.astype(np.float32) * 1e3).tobytes()

    def save(self, name: str) -> dict:
        """Move the last registration's files (poses.json, merged.ply) to ``sessions/name``."""
        folder = confined(self.sessions, name)
        if folder.parent != self.sessions or name.startswith("."):
            raise RangekitError(f"name: {name!r}: a folder name directly under the sessions folder")
        with self._cond:
            if self.state is not JobState.DONE:
                raise RangekitError("nothing to save: register the clouds first")
            if folder.exists():
                raise RangekitError(f"name: {name}: exists under the sessions folder; choose another name")
            os.replace(self.sessions / STAGING, folder)
            self.fields = {**self.fields, "saved": name}
        self.changed()
        return self.snapshot()
