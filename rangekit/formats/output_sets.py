"""What each command writes into its ``--out`` folder (a "set" of files), so that one command does not
write into another's set and leave the two mixed: ``rangekit check --out S`` replacing a session's
``rig.json``, or ``rangekit register --out S`` rewriting a processed session's ``poses.json`` while its
``summary.json`` and ``mesh.ply`` still describe the old run.

:func:`claim_folder` runs before any work: a folder holding another command's set is refused unless the
user passes ``--force``; it returns the function to call once the command has written its own files,
which removes the members of the set found there that this run did not rewrite (with ``--force``, the
other command's whole set; on a rerun of the same command, what the earlier run wrote and this one did
not, such as a ``mesh.ply`` after ``--no-mesh``). Files that belong to no set are never touched.
"""

from __future__ import annotations

import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from rangekit.errors import UsageError

__all__ = ["OutputSet", "OUTPUT_SETS", "set_in", "claim_folder"]


@dataclass(frozen=True)
class OutputSet:
    name: str                    # the key the commands use
    what: str                    # for messages: "a scan session (rangekit scan)"
    markers: tuple[str, ...]     # a file that only this set writes: its presence identifies the set
    members: tuple[str, ...]     # glob patterns of what the set consists of (files and folders)


#: Checked in this order: a processed session holds poses.json too, so the session comes first.
OUTPUT_SETS: tuple[OutputSet, ...] = (
    OutputSet("session", "a scan session (rangekit scan)", ("session.json",),
              ("session.json", ".lock", "view_*", "pass_*", "rig.json", "patterns.json", "summary.json",
               "report.html", "mesh*.*", "merged.ply", "poses.json", "events.jsonl")),
    OutputSet("capture", "a capture (rangekit sim render)", ("ground_truth.npz",),
              ("[0-9][0-9][0-9].png", "off.png", "laser*.png", "left.png", "right.png", "tof.json", "capture.json",
               "patterns.json", "rig.json", "ground_truth.npz", "preview.png")),
    OutputSet("check", "a check (rangekit check)", ("check.json",), ("check.json", "check.png", "rig.json")),
    OutputSet("registration", "registered scans (rangekit register)", ("poses.json",),
              ("poses.json", "merged.ply", "mesh.ply")),
    OutputSet("photometric", "photometric stereo results (rangekit photometric)", ("normals.npy",),
              ("normals.npy", "normals.png", "albedo.png", "depth.npy", "mesh.ply")),
)
_BY_NAME = {s.name: s for s in OUTPUT_SETS}


def set_in(folder: str | Path) -> OutputSet | None:
    """The set ``folder`` holds (the first of :data:`OUTPUT_SETS` whose marker is there), or None."""
    folder = Path(folder)
    return next((s for s in OUTPUT_SETS if any((folder / m).is_file() for m in s.markers)), None)


def claim_folder(folder: str | Path, writes: str, *, force: bool, option: str = "--out") -> Callable[[], list[str]]:
    """Check that the command writing the set ``writes`` may use ``folder``; returns ``replace()``, to call
    after the command wrote its files: it removes the members of the set found there that were not
    rewritten since this call, and returns their names. UsageError (exit 2) names the set found and the
    way out when it belongs to another command and ``force`` is False."""
    mine = _BY_NAME[writes]
    found = set_in(folder) if Path(folder).is_dir() else None
    if found is not None and found is not mine and not force:
        marker = next(m for m in found.markers if (Path(folder) / m).is_file())
        raise UsageError(f"{option} {folder}: holds {found.what} ({marker}); writing {mine.what.split(' (')[0]} "
                         f"there would leave the two mixed: choose another folder, or pass --force to replace "
                         f"that set")
    started = time.time()

    def replace() -> list[str]:
        if found is None:
            return []
        removed = []
        for pattern in found.members:
            for path in sorted(Path(folder).glob(pattern)):
                if path.is_symlink() or path.is_file():
                    if os.lstat(path).st_mtime >= started:
                        continue   # written by this run
                    path.unlink()
                elif path.is_dir():
                    if found is mine:
                        continue   # a rerun keeps its own folders (e.g. a session's views)
                    shutil.rmtree(path)
                else:
                    continue
                removed.append(path.name)
        return removed

    return replace
