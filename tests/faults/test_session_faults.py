"""Sessions nobody can corrupt (issue 16): frames checked by SHA-256, a malformed session.json, the
simulated object's path, a damaged view cache, resume options that differ from the session, the lock,
process outputs written as a set, and a full disk mid-scan.

Sessions are small: 4 views of the lumpy object, Gray code, a 320x256 camera (about 3 s to acquire,
once per module); each test works on a copy.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest

from _faults import ROOT, assert_error, cli_process
from rangekit.app.acquire import acquire
from rangekit.coded.patterns import make_pattern_spec
from rangekit.formats.session import ScanPlan, Session, SimulatorSettings
from rangekit.formats.session_check import verify_views
from rangekit.io import read_png, write_png
from rangekit.rig import Rig
from rangekit.sim import ImagingModel, SimRig, default_rig, default_scene

N_VIEWS = 4


def small_rig() -> Rig:
    r = default_rig()
    return Rig(cameras=(r.camera.resized(320, 256),), projector=r.projector, T_world_table=r.T_world_table)


@pytest.fixture(scope="module")
def reference(tmp_path_factory) -> Path:
    """A finished simulated session as ``rangekit scan`` makes it (object lumpy, seed 1, graycode)."""
    out = tmp_path_factory.mktemp("reference") / "s"
    devices = SimRig(default_scene("lumpy"), small_rig(), seed=1)
    acquire(devices, devices.rig, make_pattern_spec("graycode", (1280, 800)), out, plan=ScanPlan(N_VIEWS),
            simulator=SimulatorSettings("lumpy", 1, asdict(ImagingModel())))
    return out


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
    """Every file's bytes (the lock file aside: it holds the last user's pid by design)."""
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and p.name != ".lock"}


def frames(folder: Path) -> dict:
    """Every view's frames (bytes) and the recorded checksums: what a resumed scan must reproduce."""
    data = json.loads((folder / "session.json").read_text())
    return {"frames": {p.relative_to(folder).as_posix(): p.read_bytes() for p in sorted(folder.glob("view_*/*.png"))},
            "views": data["views"]}


def no_leftovers(folder: Path) -> None:
    assert not [p for p in folder.rglob("*") if p.name.endswith(".tmp") or p.name.endswith(".partial")]


# -- 1. frames checked by content ---------------------------------------------------------------------

def _invert(p: Path) -> None:
    write_png(p, np.iinfo(read_png(p).dtype).max - read_png(p))


def _flip_a_byte(p: Path) -> None:
    data = bytearray(p.read_bytes())
    data[len(data) // 2] ^= 0x01
    p.write_bytes(bytes(data))


DAMAGE = {
    "inverted": (lambda d: _invert(d / "view_001" / "005.png"), ["005.png", "has changed"]),
    "one bit flipped": (lambda d: _flip_a_byte(d / "view_001" / "005.png"), ["005.png", "has changed"]),
    "deleted": (lambda d: (d / "view_001" / "005.png").unlink(), ["005.png", "is missing"]),
    "extra": (lambda d: shutil.copy(d / "view_001" / "000.png", d / "view_001" / "044.png"), ["044.png", "is extra"]),
    "view folder deleted": (lambda d: shutil.rmtree(d / "view_001"), ["view_001", "missing"]),
}


@pytest.mark.parametrize("command", ["process", "resume"])
@pytest.mark.parametrize("damage", DAMAGE)
def test_a_changed_missing_or_extra_frame_is_named(cli, reference, tmp_path, damage, command):
    d = copy_session(reference, tmp_path / "s")
    do, mentions = DAMAGE[damage]
    do(d)
    before = snapshot(d)
    run = cli("process", d) if command == "process" else cli("scan", "--resume", d, "--no-process")
    assert_error(run, 1, "view_001", *mentions)
    assert snapshot(d) == before and not (d / "summary.json").exists()
    no_leftovers(d)


def test_a_session_without_checksums_loads_unverified_and_resume_records_them(cli, reference, tmp_path):
    d = copy_session(reference, tmp_path / "s", pending=(3,), checksums=False)
    run = cli("scan", "--resume", d, "--no-process")
    assert run.code == 0, run.err
    assert "view_000, view_001, view_002: no frame checksums" in run.out and "not verified" in run.out
    session = Session.load(d)
    assert [v.sha256 is None for v in session.views] == [True, True, True, False]
    assert verify_views(session) == ["view_000", "view_001", "view_002"]
    assert snapshot(d)["view_003/000.png"] == (reference / "view_003" / "000.png").read_bytes()
    # Even without checksums, a missing frame is named, never a view silently dropped.
    (d / "view_002" / "010.png").unlink()
    assert_error(cli("process", d), 1, "view_002", "010.png", "is missing")


def test_checksums_are_those_of_the_written_bytes(reference):
    import hashlib

    session = Session.load(reference)
    assert all(v.done and len(v.sha256) == session.pattern.n_frames for v in session.views)
    for v in session.views:
        for name, digest in v.sha256.items():
            assert hashlib.sha256((v.folder / name).read_bytes()).hexdigest() == digest
    assert verify_views(session) == []


# -- 2. malformed session.json -------------------------------------------------------------------------

def _set(*keys, value):
    def mutate(data):
        target = data
        for k in keys[:-1]:
            target = target[k]
        target[keys[-1]] = value
        return data
    return mutate


def _delete(*keys):
    def mutate(data):
        target = data
        for k in keys[:-1]:
            target = target[k]
        del target[keys[-1]]
        return data
    return mutate


MALFORMED = {
    "index as string": (_set("views", 0, "index", value="0"), ["views[0].index", "'0'"]),
    "empty view list": (_set("views", value=[]), ["views", "4 as in plan.n_views", "[]"]),
    "missing plan": (_delete("plan"), ["missing 'plan'"]),
    "missing n_views": (_delete("plan", "n_views"), ["plan", "missing 'n_views'"]),
    "n_views as string": (_set("plan", "n_views", value="4"), ["plan.n_views", "'4'"]),
    "wrong schema": (_set("schema", value="rangekit.session/9"), ["schema", "rangekit.session/1", "session/9"]),
    "not an object": (lambda data: [data], ["expected a JSON object", "list"]),
    "seed -1": (_set("simulator", "seed", value=-1), ["simulator.seed", "0..4294967295", "-1"]),
    "huge seed": (_set("simulator", "seed", value=10**30), ["simulator.seed", str(10**30)]),
    "seed as float": (_set("simulator", "seed", value=1.5), ["simulator.seed", "1.5"]),
    "nan angle": (_set("views", 1, "angle_rad", value=float("nan")), ["views[1].angle_rad", "nan"]),
    "angle off the plan": (_set("views", 1, "angle_rad", value=0.5), ["views[1].angle_rad", "0.5"]),
    "unknown state": (_set("views", 0, "state", value="finished"), ["views[0].state", "'finished'"]),
    "folder outside": (_set("views", 0, "folder", value="../../etc"), ["views[0].folder", "'view_000'"]),
    "bits as string": (_set("capture", "bits", value="12"), ["capture.bits", "'12'"]),
    "negative wait": (_set("capture", "pattern_delay_s", value=-1), ["capture.pattern_delay_s", "-1"]),
    "bad checksum": (_set("views", 0, "sha256", "000.png", value="xyz"), ["views[0].sha256['000.png']", "'xyz'"]),
    "checksum list": (_set("views", 0, "sha256", value=[]), ["views[0].sha256", "[]"]),
    "unknown field": (_set("extra", value=1), ["unknown field(s) 'extra'"]),
    "object ../../etc/passwd": (_set("simulator", "object", value="../../etc/passwd"),
                                ["simulator.object", "'..'", "../../etc/passwd"]),
    "object absolute": (_set("simulator", "object", value="/etc/passwd"), ["simulator.object", "absolute"]),
    "object number": (_set("simulator", "object", value=7), ["simulator.object", "7"]),
}


@pytest.mark.parametrize("command", ["process", "resume"])
@pytest.mark.parametrize("case", MALFORMED)
def test_a_malformed_session_json_names_the_field(cli, reference, tmp_path, case, command):
    d = copy_session(reference, tmp_path / "s")
    mutate, mentions = MALFORMED[case]
    (d / "session.json").write_text(json.dumps(mutate(json.loads((d / "session.json").read_text()))))
    before = snapshot(d)
    run = cli("process", d) if command == "process" else cli("scan", "--resume", d, "--no-process")
    assert_error(run, 1, "session.json", *mentions)
    assert snapshot(d) == before
    no_leftovers(d)


@pytest.mark.parametrize("text, mention", [("{", "cannot read session manifest"),
                                           ("1" * 5000, "cannot read session manifest"),
                                           ("[" * 100_000, "cannot read session manifest"),
                                           ("", "cannot read session manifest")])
def test_a_session_json_that_is_not_json(cli, reference, tmp_path, text, mention):
    d = copy_session(reference, tmp_path / "s")
    (d / "session.json").write_text(text)
    assert_error(cli("scan", "--resume", d, "--no-process"), 1, "session.json", mention)
    assert_error(cli("process", d), 1, "session.json", mention)


def test_resume_with_imaging_the_simulator_does_not_know(cli, reference, tmp_path):
    d = copy_session(reference, tmp_path / "s", pending=(3,))
    data = json.loads((d / "session.json").read_text())
    data["simulator"]["imaging"]["bogus"] = 1
    (d / "session.json").write_text(json.dumps(data))
    assert_error(cli("scan", "--resume", d, "--no-process"), 1, "session.json", "simulator.imaging", "bogus")
    assert not (d / "view_003").exists()


# -- 3. the simulated object stays inside the session -------------------------------------------------

@pytest.fixture(scope="module")
def small_mesh(tmp_path_factory) -> Path:
    from rangekit.formats.meshes import save_mesh
    from rangekit.sim.objects import make_object
    from rangekit.surface.mesh import TriangleMesh

    ob = make_object("sphere")
    path = tmp_path_factory.mktemp("mesh") / "ball.ply"
    save_mesh(path, TriangleMesh(ob.vertices, ob.triangles))
    return path


def test_a_mesh_object_is_copied_into_the_session_and_resumes_from_anywhere(cli, small_mesh, tmp_path,
                                                                            monkeypatch):
    from rangekit.app.scan import prepare_scan

    # What `rangekit scan --out DIR --object ball.ply` acquires: the session keeps its own copy.
    setup = prepare_scan(out=str(tmp_path / "new"), obj=str(small_mesh), n_views=2, patterns="white")
    assert setup.simulator.object == "object/ball.ply"
    assert setup.files == {"object/ball.ply": small_mesh.read_bytes()}
    d = tmp_path / "s"   # the same on the small camera
    devices = SimRig(default_scene(str(small_mesh)), small_rig(), seed=1)
    acquire(devices, devices.rig, setup.spec, d, plan=ScanPlan(2), simulator=setup.simulator, files=setup.files)
    assert json.loads((d / "session.json").read_text())["simulator"]["object"] == "object/ball.ply"
    assert (d / "object" / "ball.ply").read_bytes() == small_mesh.read_bytes()
    assert Session.load(d).simulator_object == str(d / "object" / "ball.ply")
    # The original may go, and the scan resume from another folder: the session has its own copy.
    moved = tmp_path / "elsewhere.ply"
    small_mesh.rename(moved)
    try:
        monkeypatch.chdir(tmp_path)
        data = json.loads((d / "session.json").read_text())
        data["views"][1]["state"] = "pending"
        data["views"][1].pop("sha256")
        (d / "session.json").write_text(json.dumps(data))
        run = cli("scan", "--resume", d, "--no-process", "--object", moved)   # the same mesh, elsewhere
        assert run.code == 0, run.err
        assert all(v.done for v in Session.load(d).views) and verify_views(Session.load(d)) == []
    finally:
        moved.rename(small_mesh)
    # A mesh that is not the session's is another object.
    other = tmp_path / "other.ply"
    other.write_bytes(small_mesh.read_bytes() + b"\n")
    assert_error(cli("scan", "--resume", d, "--no-process", "--object", other), 2, "--object", str(other),
                 "'object/ball.ply'")


@pytest.mark.slow
def test_scan_out_with_a_mesh_object_records_its_copy(cli, small_mesh, tmp_path):
    d = tmp_path / "s"
    run = cli("scan", "--out", d, "--object", small_mesh, "--views", "2", "--patterns", "white", "--no-process")
    assert run.code == 0, run.err
    assert json.loads((d / "session.json").read_text())["simulator"]["object"] == "object/ball.ply"
    assert (d / "object" / "ball.ply").read_bytes() == small_mesh.read_bytes()


def test_an_object_linked_out_of_the_session_is_refused(cli, reference, tmp_path):
    d = copy_session(reference, tmp_path / "s")
    (d / "object").mkdir()
    (d / "object" / "evil.ply").symlink_to("/etc/passwd")
    data = json.loads((d / "session.json").read_text())
    data["simulator"]["object"] = "object/evil.ply"
    (d / "session.json").write_text(json.dumps(data))
    assert_error(cli("process", d), 1, "session.json", "simulator.object", "a link out of the session folder")


# -- 4. a damaged view cache is rebuilt ----------------------------------------------------------------

def _cache_args(session):
    from rangekit.geometry import invert_T

    settings = {"method": "auto", "table_margin": 0.002, "pattern": "graycode", "full_scale": None,
                "projector_response": None}
    return (session.pattern, session.rig, settings, None, invert_T(session.rig.T_world_table), 0.002)


def _npz_without_depth(p: Path) -> None:
    with np.load(p) as z:
        arrays = {k: z[k] for k in ("proj_col", "confidence")}
    np.savez(p, **arrays)


CACHE_DAMAGE = {
    "cloud.json not JSON": lambda v: (v / "cloud.json").write_text("{"),
    "cloud.json a list": lambda v: (v / "cloud.json").write_text("[]"),
    "cloud.ply truncated": lambda v: (v / "cloud.ply").write_bytes((v / "cloud.ply").read_bytes()[:500]),
    "cloud.ply another cloud": lambda v: (v / "cloud.ply").write_bytes((v.parent / "view_000" / "cloud.ply").read_bytes()),
    "maps.npz garbage": lambda v: (v / "maps.npz").write_bytes(b"PK\x03\x04 not a zip"),
    "maps.npz without depth": lambda v: _npz_without_depth(v / "maps.npz"),
    "maps.npz deleted": lambda v: (v / "maps.npz").unlink(),
}


@pytest.mark.parametrize("damage", CACHE_DAMAGE)
def test_a_damaged_view_cache_is_rebuilt(reference, tmp_path, damage):
    from rangekit.app.view_cache import view_cloud

    d = copy_session(reference, tmp_path / "s")
    session = Session.load(d)
    first = [view_cloud(v, *_cache_args(session)) for v in session.views[:2]]
    v = session.views[1].folder
    cache = {n: (v / n).read_bytes() for n in ("cloud.ply", "maps.npz", "cloud.json")}
    assert "sha256" in json.loads(cache["cloud.json"])
    CACHE_DAMAGE[damage](v)
    cloud, maps = view_cloud(session.views[1], *_cache_args(session))
    assert np.array_equal(cloud.points, first[1][0].points)
    assert np.array_equal(maps.depth, first[1][1].depth, equal_nan=True)
    assert {n: (v / n).read_bytes() for n in cache} == cache   # rebuilt to the same bytes
    no_leftovers(d)


# -- 5. resume options that differ from the session ----------------------------------------------------

@pytest.mark.parametrize("option, value, recorded", [
    ("--views", "5", "4"), ("--object", "sphere", "'lumpy'"), ("--seed", "2", "1"),
    ("--patterns", "hybrid", "'graycode'"), ("--rig", "my_rig.json", "'sim'"),
])
def test_resume_with_an_option_that_differs_from_the_session_stops(cli, reference, tmp_path, option, value,
                                                                   recorded):
    d = copy_session(reference, tmp_path / "s", pending=(3,))
    before = snapshot(d)
    assert_error(cli("scan", "--resume", d, "--no-process", option, value), 2, option, value, recorded, str(d))
    assert snapshot(d) == before and not (d / "view_003").exists()


def test_resume_with_the_sessions_own_options_goes_on(cli, reference, tmp_path):
    d = copy_session(reference, tmp_path / "s", pending=(3,))
    run = cli("scan", "--resume", d, "--no-process", "--views", "4", "--object", "lumpy", "--seed", "1",
              "--patterns", "graycode", "--rig", "sim")
    assert run.code == 0, run.err
    assert frames(d) == frames(reference)
    no_leftovers(d)


# -- 6. one process per session ------------------------------------------------------------------------

def _wait_for_lock(folder: Path, pid: int, proc: subprocess.Popen, timeout: float = 120.0) -> None:
    t = time.monotonic()
    while time.monotonic() - t < timeout:
        if (folder / ".lock").exists() and (folder / ".lock").read_text().strip() == str(pid):
            return
        assert proc.poll() is None, proc.communicate()
        time.sleep(0.02)
    raise AssertionError("the child never took the lock")


def test_a_second_process_of_a_session_in_use_stops_at_once(cli, reference, tmp_path):
    d = copy_session(reference, tmp_path / "s", pending=(2, 3))
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    child = subprocess.Popen([sys.executable, "-m", "rangekit", "scan", "--resume", str(d), "--no-process"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                             preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        _wait_for_lock(d, child.pid, child)
        second = cli("scan", "--resume", d, "--no-process")
        third = cli("process", d)
        running = child.poll() is None
        out, err = child.communicate(timeout=300)
    finally:
        if child.poll() is None:
            child.kill()
    assert running, "the first scan ended before the others tried: the test proved nothing"
    for run in (second, third):
        assert_error(run, 1, str(d), f"pid {child.pid}", "in use by another rangekit process")
    assert child.returncode == 0, err
    # The first one finished undisturbed: the same frames as the uninterrupted reference.
    assert frames(d) == frames(reference)
    no_leftovers(d)


def test_a_stale_lock_of_a_dead_process_is_taken_over(cli, reference, tmp_path):
    d = copy_session(reference, tmp_path / "s", pending=(3,))
    dead = subprocess.Popen(["true"])
    dead.wait()
    (d / ".lock").write_text(f"{dead.pid}\n")
    run = cli("scan", "--resume", d, "--no-process")
    assert run.code == 0, run.err
    assert (d / ".lock").read_text().strip() == str(os.getpid())
    assert frames(d) == frames(reference)


def test_the_lock_is_held_for_the_whole_block_and_released(tmp_path):
    from rangekit.formats.session_lock import SessionLocked, session_lock

    with session_lock(tmp_path):
        with session_lock(tmp_path):   # re-entrant in one process
            pass
        # Another open file description (as another process would have) cannot take it.
        import fcntl

        fd = os.open(tmp_path / ".lock", os.O_RDWR)
        with pytest.raises(BlockingIOError):
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        os.close(fd)
    with session_lock(tmp_path):
        pass
    assert issubclass(SessionLocked, Exception)


# -- 7. process writes its outputs as a set ------------------------------------------------------------

def test_a_process_that_fails_between_outputs_leaves_no_summary(cli, reference, tmp_path):
    d = copy_session(reference, tmp_path / "s")
    assert cli("process", d, "--no-report").code == 0   # the view caches, then every output
    sizes = {name: (d / name).stat().st_size for name in ("poses.json", "merged.ply", "mesh.ply")}
    for name in sizes:
        (d / name).unlink()
    (d / "summary.json").write_text('{"stale": true}')   # from an earlier run
    limit = sizes["merged.ply"] // 2
    assert sizes["poses.json"] < limit

    def small_files():  # files above the limit fail with EFBIG, as on a full disk: poses.json fits, merged.ply not
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    run = cli_process("process", d, "--no-report", preexec_fn=small_files)
    assert_error(run, 1, "merged.ply", "File too large")
    assert (d / "poses.json").exists() and not (d / "summary.json").exists() and not (d / "mesh.ply").exists()
    no_leftovers(d)


def test_every_rename_of_acquisition_is_followed_by_a_folder_fsync(tmp_path, monkeypatch):
    acq = sys.modules[acquire.__module__]
    events = []
    real_rename = Path.rename
    monkeypatch.setattr(Path, "rename", lambda self, target: (events.append(("rename", Path(target).parent)),
                                                              real_rename(self, target))[1])
    monkeypatch.setattr(acq, "fsync_folder", lambda folder: events.append(("fsync", Path(folder))))
    devices = SimRig(default_scene("sphere"), small_rig(), seed=1)
    acquire(devices, devices.rig, make_pattern_spec("white", (1280, 800)), tmp_path / "s", plan=ScanPlan(2))
    renames = [i for i, e in enumerate(events) if e[0] == "rename"]
    assert len(renames) == 2
    assert all(events[i + 1] == ("fsync", events[i][1]) for i in renames)
    assert events[0] == ("fsync", tmp_path)   # the new session folder's entry


# -- 8. a full disk mid-scan -----------------------------------------------------------------------------

def test_a_full_disk_mid_scan_says_how_to_resume_and_the_resume_completes(cli, reference, tmp_path):
    d = copy_session(reference, tmp_path / "s", pending=(3,))
    before = snapshot(d)
    limit = min(p.stat().st_size for p in (d / "view_000").glob("*.png")) // 2
    assert limit > 1000   # the lock file and the first bytes fit, a frame does not

    def small_files():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)   # writes past the limit fail with EFBIG
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    run = cli_process("scan", "--resume", d, "--no-process", preexec_fn=small_files)
    assert_error(run, 1, "view 3", "000.png", "File too large", f"rangekit scan --resume {d}")
    assert snapshot(d) == before   # finished views intact, nothing half-written
    no_leftovers(d)
    assert cli("scan", "--resume", d, "--no-process").code == 0
    assert frames(d) == frames(reference)


@pytest.fixture
def small_disk(tmp_path):
    mount = tmp_path / "disk"
    mount.mkdir()
    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root")
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=16m", "tmpfs", str(mount)], capture_output=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.decode()[:200]}")
    yield mount
    subprocess.run(["umount", "-l", str(mount)], check=False)


def test_a_disk_that_fills_up_mid_scan_keeps_every_finished_view(cli, reference, small_disk, monkeypatch):
    import rangekit.cli._common as common

    monkeypatch.setattr(common, "MIN_FREE_BYTES", 0)   # the disk is small from the start
    d = copy_session(reference, small_disk / "s", pending=(1, 2, 3))
    view_bytes = sum(p.stat().st_size for p in (reference / "view_001").iterdir())
    free = shutil.disk_usage(small_disk).free
    (small_disk / "filler").write_bytes(b"\0" * (free - int(1.5 * view_bytes)))
    run = cli("scan", "--resume", d, "--no-process")
    assert_error(run, 1, "No space left", f"rangekit scan --resume {d}")
    session = Session.load(d)
    n_done = len(session.done_views)
    assert n_done == 2 and verify_views(session) == []   # view_001 finished before the disk filled up
    assert not (d / "view_002").exists()
    no_leftovers(d)
    (small_disk / "filler").unlink()
    assert cli("scan", "--resume", d, "--no-process").code == 0
    assert frames(d) == frames(reference)
