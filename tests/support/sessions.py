"""Small simulated sessions: the reference session and what the tests do with copies of it. The
``reference_session`` fixture (tests/conftest.py) makes it once per run.

Sessions are small: 4 views of the lumpy object, Gray code, a 320x256 camera (about 3 s to acquire).
"""

from __future__ import annotations

import json
import shutil
from dataclasses import asdict
from pathlib import Path

from rangekit.app.acquire.acquire import acquire
from rangekit.coded.patterns import make_pattern_spec
from rangekit.formats.sessions.session import ScanPlan, SimulatorSettings
from rangekit.sim import ImagingModel, SimRig, default_scene
from support.small_rigs import small_rig

N_VIEWS = 4


def make_reference(out: Path) -> Path:
    """A finished simulated session as ``rangekit scan`` makes it (object lumpy, seed 1, graycode)."""
    devices = SimRig(default_scene("lumpy"), small_rig(), seed=1)
    acquire(devices, devices.rig, make_pattern_spec("graycode", (1280, 800)), out, plan=ScanPlan(N_VIEWS),
            simulator=SimulatorSettings("lumpy", 1, asdict(ImagingModel())))
    return out


def sim(seed: int = 3) -> SimRig:
    """The simulated rig of the small sessions: the lumpy object on the small rig."""
    return SimRig(default_scene("lumpy"), small_rig(), seed=seed)


def frame_paths(folder: Path, pattern: str = "view_*/*") -> list[Path]:
    """The frame files (``000.png`` or ``000.npy.zst``) matching ``pattern`` under a session folder, sorted."""
    return sorted(p for suffix in (".png", ".npy.zst") for p in folder.glob(pattern + suffix))


def pngs(folder: Path) -> dict:
    """Every finished view's frames (bytes, PNG or .npy.zst), by path relative to the session folder."""
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in frame_paths(folder)
            if not p.parent.name.endswith(".partial")}


def copy_session(reference: Path, dest: Path, pending=(), checksums: bool = True) -> Path:
    """A copy of the reference session; views in ``pending`` not yet taken; without their checksums
    (as written before rangekit recorded them) when ``checksums`` is False."""
    shutil.copytree(reference, dest)
    data = json.loads((dest / "session.json").read_text())
    for v in data["views"]:
        if v["index"] in pending:
            v["state"] = "pending"
            v.pop("sha256")
            shutil.rmtree(dest / v["folder"])
        elif not checksums:
            v.pop("sha256")
    (dest / "session.json").write_text(json.dumps(data, indent=2))
    return dest


def snapshot(folder: Path) -> dict:
    """Every file's bytes, but the lock file (it holds the last user's pid by design) and the job's journal,
    events.jsonl: a run, refused or not, appends its events to it (:func:`journal`, only ever appended)."""
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name not in (".lock", "events.jsonl")}


def journal(folder: Path) -> bytes:
    """The session's events.jsonl as it is (b"" when there is none): a later run's must begin with these bytes."""
    path = folder / "events.jsonl"
    return path.read_bytes() if path.is_file() else b""


def frames(folder: Path) -> dict:
    """Every view's frames (bytes) and the recorded checksums: what a resumed scan must reproduce."""
    data = json.loads((folder / "session.json").read_text())
    return {"frames": {p.relative_to(folder).as_posix(): p.read_bytes() for p in frame_paths(folder)},
            "views": data["views"]}


def no_leftovers(folder: Path) -> None:
    assert not [p for p in folder.rglob("*") if p.name.endswith(".tmp") or p.name.endswith(".partial")]


