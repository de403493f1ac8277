"""The Sessions page: the sessions under ``--sessions``, each with its state and figures, and the files a page
may open from one (the report, the meshes), always confined to the sessions folder."""

from __future__ import annotations

import json
from pathlib import Path

from rangekit.errors import RangekitError
from rangekit.ui.paths import confined
from rangekit.formats.sessions.files import (MERGED_FILE, MESH_FILE, POSES_FILE, PREVIEW_FILE, REPORT_FILE, SESSION_FILE,
                                             SUMMARY_FILE, WATERTIGHT_FILE)

__all__ = ["SESSION_FILES", "list_sessions", "readable_name", "session_file", "sessions_listing"]

#: The files of a session a page may open.
SESSION_FILES = (REPORT_FILE, MESH_FILE, WATERTIGHT_FILE, PREVIEW_FILE, MERGED_FILE, POSES_FILE,
                 SUMMARY_FILE, *(f"{stem}.{fmt}" for fmt in ("obj", "stl", "glb")
                                 for stem in (Path(MESH_FILE).stem, Path(WATERTIGHT_FILE).stem)))


def _summary(folder: Path) -> dict:
    try:
        s = json.loads((folder / SUMMARY_FILE).read_text())
    except (OSError, ValueError):
        return {}
    acc = s.get("accuracy") or {}
    mesh = s.get("mesh") or {}
    points = s.get("n_points")
    if isinstance(points, list):         # per view: the session's total
        points = sum(p for p in points if isinstance(p, int))
    return {"points": points, "vertices": mesh.get("vertices"),
            "rms_mm": None if acc.get("rms") is None else round(acc["rms"] * 1e3, 4),
            "completeness_percent": None if acc.get("completeness") is None else round(100 * acc["completeness"], 2)}


def readable_name(name: str) -> str | None:
    """``name`` as a page can show and send it back, or None: a name that is not UTF-8 (its bytes decoded as
    surrogates) cannot travel in JSON or a URL and is skipped, said so by :func:`sessions_listing`."""
    try:
        name.encode("utf-8")
    except UnicodeEncodeError:
        return None
    return name


def shown_bytes(name: str) -> str:
    """A name that is not UTF-8, its bytes written out (``caf\\xe9``), for the line saying it was skipped."""
    return name.encode("utf-8", "surrogateescape").decode("ascii", "backslashreplace")


def sessions_listing(sessions: Path) -> dict:
    """``{"sessions": list_sessions(...), "skipped": [one line per folder left out]}``."""
    skipped: list[str] = []
    return {"sessions": list_sessions(sessions, skipped), "skipped": skipped}


def list_sessions(sessions: Path, skipped: list[str] | None = None) -> list[dict]:
    """One dict per session folder directly under ``sessions`` (a folder with a session.json): name, views done
    and planned, state (``acquiring`` while views are pending, ``acquired``, ``processed`` with summary.json),
    its figures and the files a page may open; a session.json that does not load is listed with its error. A
    folder whose name is not UTF-8 is left out, a line saying so appended to ``skipped``."""
    from rangekit.formats.sessions.session import Session

    root = Path(sessions).resolve()
    out = []
    for folder in sorted(p for p in root.iterdir() if (p / SESSION_FILE).is_file()):
        if not folder.resolve().is_relative_to(root):      # a link out of the sessions folder is not listed
            continue
        if readable_name(folder.name) is None:
            if skipped is not None:
                skipped.append(f"{shown_bytes(folder.name)}: skipped: its name is not UTF-8; rename it to open it here")
            continue
        row = {"name": folder.name, "files": [n for n in SESSION_FILES if (folder / n).is_file()]}
        try:
            session = Session.load(folder)
        except RangekitError as exc:
            out.append({**row, "state": "unreadable", "error": str(exc)})
            continue
        done = sum(v.done for v in session.views)
        state = "processed" if SUMMARY_FILE in row["files"] else ("acquired" if done == len(session.views)
                                                                    else "acquiring")
        out.append({**row, "state": state, "views_done": done, "views": len(session.views), **_summary(folder)})
    return out


def session_file(sessions: Path, name: str, file: str) -> Path:
    """The path of ``file`` (one of :data:`SESSION_FILES`) in session ``name``, inside ``sessions``."""
    if file not in SESSION_FILES:
        raise RangekitError(f"file {file!r}: not one a page may open; expected one of {', '.join(SESSION_FILES)}")
    path = confined(sessions, f"{name}/{file}")
    if not path.is_file():
        raise RangekitError(f"{name}/{file}: not there (yet)")
    return path
