"""What each command writes into its ``--out`` folder (a "set" of files), so that one command does not
write into another's set and leave the two mixed: ``rangekit check --out S`` replacing a session's
``rig.json``, or ``rangekit register --out S`` rewriting a processed session's ``poses.json`` while its
``summary.json`` and ``mesh.ply`` still describe the old run.

:func:`claim_folder` runs before any work: a folder holding another command's set is refused unless the
user passes ``--force``; it returns the function to call once the command has written its own files,
which removes the members of the set found there that this run did not rewrite (with ``--force``, the
other command's whole set; on a rerun of the same command, what the earlier run wrote and this one did
not, such as a ``mesh.ply`` after ``--no-mesh``). Files that belong to no set are never touched.

The one rule of every command (README, "Command line"): no command writes over a file it did not make in
this run's output set, or over one of its own inputs, unless told ``--force``. A folder that holds no set
but already has a file the command would write (the user's own ``rig.json`` or ``image.png``) is refused
like a folder of another set, and an input is never taken for the command's own earlier output (paths are
resolved and compared): :func:`claim_folder` for a folder, :func:`file_owner` and
``rangekit.cli._common.check_output`` for a file.
"""

from __future__ import annotations

import os
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable

from rangekit.errors import UsageError
from rangekit.formats.sessions.files import (CLOUD_FILE, MERGED_FILE, MESH_FILE, PATTERNS_FILE, POSES_FILE, RIG_FILE,
                                             SESSION_FILE, SESSION_MEMBERS)

__all__ = ["OutputSet", "OUTPUT_SETS", "set_in", "claim_folder", "file_owner", "same_file"]


@dataclass(frozen=True)
class OutputSet:
    name: str                    # the key the commands use
    what: str                    # for messages: "a scan session (rangekit scan)"
    markers: tuple[str, ...]     # a file that only this set writes: its presence identifies the set
    members: tuple[str, ...]     # glob patterns of what the set consists of (files and folders)


#: Checked in this order: a processed session holds poses.json too, so the session comes first.
OUTPUT_SETS: tuple[OutputSet, ...] = (
    OutputSet("session", "a scan session (rangekit scan)", (SESSION_FILE,), SESSION_MEMBERS),
    OutputSet("capture", "a capture (rangekit sim render)", ("ground_truth.npz", "truth.json"),
              ("[0-9][0-9][0-9].png", "off.png", "laser*.png", "left.png", "right.png", "left", "right",
               "image.png", "reference.png", "tof.json", "samples", "round_trip_s.npy", "capture.json",
               PATTERNS_FILE, RIG_FILE, "ground_truth.npz", "preview.png",
               # a laser rig's recording (--sensor laser-recording, laser-board; rangekit.sim.laser.recording)
               "off", "laser[0-9]", "[0-9][0-9][0-9][0-9][0-9].png", "steps.csv", "truth.json", "true-rig.json",
               "sweep_[0-9]*")),
    OutputSet("check", "a check (rangekit check)", ("check.json",), ("check.json", "check.png", RIG_FILE)),
    OutputSet("registration", "registered scans (rangekit register)", (POSES_FILE,),
              (POSES_FILE, MERGED_FILE, MESH_FILE)),
    OutputSet("photometric", "photometric stereo results (rangekit photometric)", ("normals.npy",),
              ("normals.npy", "normals.png", "albedo.png", "depth.npy", MESH_FILE)),
    OutputSet("depth", "depth maps (rangekit tof, stereo)", ("depth.png",),
              ("depth.npy", "depth.png", "range.npy", "confidence.npy", "confidence.png", CLOUD_FILE, "left.png",
               "right.png", RIG_FILE, "device_depth.npy", "device_depth.png")),
)
_BY_NAME = {s.name: s for s in OUTPUT_SETS}


def set_in(folder: str | Path) -> OutputSet | None:
    """The set ``folder`` holds (the first of :data:`OUTPUT_SETS` whose marker is there), or None."""
    folder = Path(folder)
    return next((s for s in OUTPUT_SETS if any((folder / m).is_file() for m in s.markers)), None)


def same_file(path: str | Path, inputs: Iterable[str | Path], *, within: bool = True) -> Path | None:
    """The input of ``inputs`` that ``path`` is (paths resolved, links followed), or with ``within`` the input
    folder it lies in (directly: a capture folder's own files); None when it is none of them."""
    target = Path(path).resolve()
    for given in inputs:
        if given is None:
            continue
        where = Path(given).resolve()
        if target == where or (within and target.parent == where):
            return Path(given)
    return None


def file_owner(path: str | Path) -> OutputSet | None:
    """The set of :data:`OUTPUT_SETS` the file ``path`` belongs to: its folder holds that set (its marker) and
    the name is one of the set's members; None otherwise."""
    path = Path(path)
    found = set_in(path.parent) if path.parent.is_dir() else None
    if found is None or not any(path.match(m) for m in found.members):
        return None
    return found


def claim_folder(folder: str | Path, writes: str, *, force: bool, option: str = "--out", inputs=(),
                 names: Iterable[str] | None = None) -> Callable[[], list[str]]:
    """Check that the command writing the set ``writes`` may use ``folder``; returns ``replace()``, to call
    after the command wrote its files: it removes the members of the set found there that were not
    rewritten since this call (never one of ``inputs``), and returns their names. Without ``force``, a
    UsageError (exit 2) names the way out when the folder holds another command's set, when it holds no
    set but a file this command writes (``names``: the member patterns this run writes, default all of the
    set's), or when a file it writes or may remove there is one of the command's ``inputs``."""
    mine = _BY_NAME[writes]
    folder_path = Path(folder)
    found = set_in(folder) if folder_path.is_dir() else None
    short = mine.what.split(" (")[0]
    if found is not None and found is not mine and not force:
        marker = next(m for m in found.markers if (folder_path / m).is_file())
        raise UsageError(f"{option} {folder}: holds {found.what} ({marker}); writing {short} "
                         f"there would leave the two mixed: choose another folder, or pass --force to replace "
                         f"that set")
    inputs = [p for p in inputs if p is not None]
    if not force and folder_path.is_dir():
        patterns = list(mine.members if names is None else names)
        for pattern in patterns if found is None else mine.members:   # a rerun may remove any member
            for path in sorted(folder_path.glob(pattern)):
                # an input file; the other files of an input folder are not read (photometric DIR --out DIR)
                given = same_file(path, inputs, within=False)
                if given is not None:
                    raise UsageError(f"{option} {folder}: {path} is this command's input {given}; writing {short} "
                                     f"there would replace it: choose another folder, or pass --force")
                if found is None and any(path.match(p) for p in patterns):
                    raise UsageError(f"{option} {folder}: {path} exists and was not written by "
                                     f"{mine.what.split(' (')[1].rstrip(')')} (no {mine.markers[0]} beside it): "
                                     f"choose another folder, or pass --force to overwrite it")
    started = time.time()

    def replace() -> list[str]:
        if found is None:
            return []
        removed = []
        for pattern in found.members:
            for path in sorted(Path(folder).glob(pattern)):
                if same_file(path, inputs) is not None:
                    continue   # an input is never removed
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
