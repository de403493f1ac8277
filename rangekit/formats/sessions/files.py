"""The names of a session folder's files, in one place: every module that reads, writes, lists or names one
of them (in a path or a message) takes it from here, and ``tests/formats/test_session_files.py`` fails on any
of these names written as a literal anywhere else in rangekit.

A session folder (``rangekit scan``, then ``rangekit process``)::

    session.json          the manifest (rangekit.formats.sessions.session)
    .lock                 held by the process working on the session (rangekit.formats.sessions.lock)
    rig.json              the rig file the session was taken with; every capture folder has one too
    patterns.json         the pattern set; every capture folder has one too
    events.jsonl          the job's events, a line each (rangekit.app.event_log)
    view_000/ ...         one capture folder per finished view (``view_000.partial/`` while it is taken):
        view.json           the view's index, turntable angle and times
        cloud.ply           its decoded cloud (the view cache; also the depth commands' cloud)
        cloud.json          the settings and checksums of that cache
        maps.npz            what its decoding leaves per camera pixel (rangekit.formats.sessions.view_maps)
    preview.ply           the cloud fused while the scan runs
    poses.json            the registered poses (also ``rangekit register``'s)
    merged.ply            the registered views' points (also ``rangekit register``'s)
    mesh.ply              the observed mesh (also ``rangekit register``'s and ``photometric``'s)
    mesh_watertight.ply   the closed mesh
    summary.json          the figures (rangekit.formats.sessions.summary)
    report.html           the report page

:data:`SESSION_MEMBERS` is the session's output set (``rangekit.formats.output_sets``): the glob patterns of
what a session consists of.
"""

from __future__ import annotations

from pathlib import Path

__all__ = ["SESSION_FILE", "LOCK_FILE", "RIG_FILE", "PATTERNS_FILE", "EVENTS_FILE", "VIEW_FILE", "CLOUD_FILE",
           "CLOUD_INFO_FILE", "MAPS_FILE", "PREVIEW_FILE", "POSES_FILE", "MERGED_FILE", "MESH_FILE",
           "WATERTIGHT_FILE", "SUMMARY_FILE", "REPORT_FILE", "FILE_NAMES", "VIEW_PREFIX", "PARTIAL_SUFFIX",
           "view_name", "view_folder", "partial_view_folder", "SESSION_MEMBERS"]

SESSION_FILE = "session.json"
LOCK_FILE = ".lock"
RIG_FILE = "rig.json"
PATTERNS_FILE = "patterns.json"
EVENTS_FILE = "events.jsonl"
VIEW_FILE = "view.json"
CLOUD_FILE = "cloud.ply"
CLOUD_INFO_FILE = "cloud.json"
MAPS_FILE = "maps.npz"
PREVIEW_FILE = "preview.ply"
POSES_FILE = "poses.json"
MERGED_FILE = "merged.ply"
MESH_FILE = "mesh.ply"
WATERTIGHT_FILE = "mesh_watertight.ply"
SUMMARY_FILE = "summary.json"
REPORT_FILE = "report.html"

#: Every file name above, for the test that no other module writes one as a literal.
FILE_NAMES: tuple[str, ...] = (SESSION_FILE, LOCK_FILE, RIG_FILE, PATTERNS_FILE, EVENTS_FILE, VIEW_FILE, CLOUD_FILE,
                               CLOUD_INFO_FILE, MAPS_FILE, PREVIEW_FILE, POSES_FILE, MERGED_FILE, MESH_FILE,
                               WATERTIGHT_FILE, SUMMARY_FILE, REPORT_FILE)

VIEW_PREFIX = "view_"          # a view's folder: view_NNN
PARTIAL_SUFFIX = ".partial"    # a view's folder while it is taken: view_NNN.partial


def view_name(index: int) -> str:
    """The name of view ``index``'s folder: ``view_NNN`` (three digits at least)."""
    return f"{VIEW_PREFIX}{index:03d}"


def view_folder(folder: str | Path, index: int) -> Path:
    """The folder of view ``index`` in the session folder ``folder``: ``folder/view_NNN``."""
    return Path(folder) / view_name(index)


def partial_view_folder(folder: str | Path, index: int) -> Path:
    """Where view ``index`` is taken before it is complete: ``folder/view_NNN.partial`` (renamed to
    :func:`view_folder` once all its frames are on disk)."""
    return Path(folder) / (view_name(index) + PARTIAL_SUFFIX)


#: The session's output set: glob patterns of its files and folders (``pass_*``: a multi-pass session's).
SESSION_MEMBERS: tuple[str, ...] = (SESSION_FILE, LOCK_FILE, VIEW_PREFIX + "*", "pass_*", RIG_FILE, PATTERNS_FILE,
                                    SUMMARY_FILE, REPORT_FILE, "mesh*.*", MERGED_FILE, POSES_FILE, EVENTS_FILE)
