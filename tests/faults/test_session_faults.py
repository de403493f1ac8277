"""Sessions nobody can corrupt, what a session holds: frames checked by SHA-256, a malformed
session.json, the simulated object's path, a damaged view cache. (What a run does to it: test_session_runs.py.)
Each test works on a copy of the small reference session (tests/support/sessions.py).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from support.cli_runs import assert_error
from support.sessions import copy_session, journal, no_leftovers, snapshot
from support.small_rigs import small_rig
from rangekit.app.acquire.acquire import acquire
from rangekit.formats.sessions.session import ScanPlan, Session
from rangekit.io import read_png, write_png
from rangekit.formats.sessions.check import file_sha256, verify_views
from rangekit.sim import SimRig, default_scene


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
def test_a_changed_missing_or_extra_frame_is_named(cli, reference_session, tmp_path, damage, command):
    d = copy_session(reference_session, tmp_path / "s")
    do, mentions = DAMAGE[damage]
    do(d)
    before, log = snapshot(d), journal(d)
    run = cli("process", d) if command == "process" else cli("scan", "--resume", d, "--no-process")
    assert_error(run, 1, "view_001", *mentions)
    after = snapshot(d)
    # Every file as it was; processing checks a frame as it reads it to decode, two views at a time, so the
    # other views may have their caches written (complete and valid ones), the damaged view none.
    new = set(after) - set(before)
    assert {k: after[k] for k in before} == before and not (d / "summary.json").exists()
    assert journal(d).startswith(log)     # the run's events (its failure too) only appended
    assert all(name.split("/")[0] != "view_001" and name.split("/")[1] in ("cloud.ply", "maps.npz", "cloud.json")
               for name in new), new
    for view in {name.split("/")[0] for name in new}:
        meta = json.loads((d / view / "cloud.json").read_text())
        assert {name: file_sha256(d / view / name) for name in meta["sha256"]} == meta["sha256"]
    no_leftovers(d)


def test_a_session_without_checksums_loads_unverified_and_resume_records_them(cli, reference_session, tmp_path):
    d = copy_session(reference_session, tmp_path / "s", pending=(3,), checksums=False)
    run = cli("scan", "--resume", d, "--no-process")
    assert run.code == 0, run.err
    assert "view_000, view_001, view_002: no frame checksums" in run.err and "not verified" in run.err  # progress
    session = Session.load(d)
    assert [v.sha256 is None for v in session.views] == [True, True, True, False]
    assert verify_views(session) == ["view_000", "view_001", "view_002"]
    assert snapshot(d)["view_003/000.png"] == (reference_session / "view_003" / "000.png").read_bytes()
    # Even without checksums, a missing frame is named, never a view silently dropped.
    (d / "view_002" / "010.png").unlink()
    assert_error(cli("process", d), 1, "view_002", "010.png", "is missing")


def test_checksums_are_those_of_the_written_bytes(reference_session):
    import hashlib

    session = Session.load(reference_session)
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
def test_a_malformed_session_json_names_the_field(cli, reference_session, tmp_path, case, command):
    d = copy_session(reference_session, tmp_path / "s")
    mutate, mentions = MALFORMED[case]
    (d / "session.json").write_text(json.dumps(mutate(json.loads((d / "session.json").read_text()))))
    before, log = snapshot(d), journal(d)
    run = cli("process", d) if command == "process" else cli("scan", "--resume", d, "--no-process")
    assert_error(run, 1, "session.json", *mentions)
    assert snapshot(d) == before and journal(d).startswith(log)
    no_leftovers(d)


@pytest.mark.parametrize("text, mention", [("{", "cannot read session manifest"),
                                           ("1" * 5000, "cannot read session manifest"),
                                           ("[" * 100_000, "cannot read session manifest"),
                                           ("", "cannot read session manifest")])
def test_a_session_json_that_is_not_json(cli, reference_session, tmp_path, text, mention):
    d = copy_session(reference_session, tmp_path / "s")
    (d / "session.json").write_text(text)
    assert_error(cli("scan", "--resume", d, "--no-process"), 1, "session.json", mention)
    assert_error(cli("process", d), 1, "session.json", mention)


def test_resume_with_imaging_the_simulator_does_not_know(cli, reference_session, tmp_path):
    d = copy_session(reference_session, tmp_path / "s", pending=(3,))
    data = json.loads((d / "session.json").read_text())
    data["simulator"]["imaging"]["bogus"] = 1
    (d / "session.json").write_text(json.dumps(data))
    assert_error(cli("scan", "--resume", d, "--no-process"), 1, "session.json", "simulator.imaging", "bogus")
    assert not (d / "view_003").exists()


# -- 3. the simulated object stays inside the session -------------------------------------------------

@pytest.fixture(scope="module")
def small_mesh(tmp_path_factory) -> Path:
    from rangekit.formats.meshes import save_mesh
    from rangekit.sim.scene.objects import make_object
    from rangekit.surface.mesh import TriangleMesh

    ob = make_object("sphere")
    path = tmp_path_factory.mktemp("mesh") / "ball.ply"
    save_mesh(path, TriangleMesh(ob.vertices, ob.triangles))
    return path


def test_a_mesh_object_is_copied_into_the_session_and_resumes_from_anywhere(cli, small_mesh, tmp_path,
                                                                            monkeypatch):
    from rangekit.app.scan.options import ScanOptions
    from rangekit.app.scan.setup import prepare_scan

    # What `rangekit scan --out DIR --object ball.ply` acquires: the session keeps its own copy.
    setup = prepare_scan(ScanOptions(out=tmp_path / "new", object=small_mesh, views=2, patterns="white"))
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


def test_an_object_linked_out_of_the_session_is_refused(cli, reference_session, tmp_path):
    d = copy_session(reference_session, tmp_path / "s")
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
def test_a_damaged_view_cache_is_rebuilt(reference_session, tmp_path, damage):
    from rangekit.app.process.view_cache import view_cloud

    d = copy_session(reference_session, tmp_path / "s")
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
