"""Many sessions on Dask (rangekit.app.batch.sessions): real worker processes, no mocks. The outputs are the
bytes of serial processing; a failing session is reported by name while the others finish; a worker
killed in the middle loses nothing and no view is decoded twice; an unreachable scheduler is a clear
error within 10 s."""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from support.sessions import N_VIEWS
from rangekit.app.batch.sessions import WORKER_ENV, SchedulerUnreachable, process_sessions
from rangekit.app.process.options import ProcessOptions
from rangekit.app.process.process import process_session
from rangekit.cli import main

ROOT = Path(__file__).resolve().parents[3]
OUTPUTS = ("mesh.ply", "mesh_watertight.ply", "poses.json", "merged.ply")


@pytest.fixture(scope="module")
def sessions(tmp_path_factory, reference_session):
    """The small reference session (4 views, 320x256) and its outputs processed serially, in one process."""
    root = tmp_path_factory.mktemp("batch")
    ref = shutil.copytree(reference_session, root / "reference")
    serial = shutil.copytree(ref, root / "serial")
    process_session(serial, ProcessOptions(report=False))
    return root, ref, {name: (serial / name).read_bytes() for name in OUTPUTS}


@pytest.fixture(scope="module")
def two_unprocessed(tmp_path_factory, reference_session):
    """The small reference session and a copy, neither processed (for the tests that stop before any work)."""
    root = tmp_path_factory.mktemp("batch_options")
    ref = shutil.copytree(reference_session, root / "reference")
    return ref, shutil.copytree(ref, root / "copy")


@pytest.fixture(scope="module")
def local_batch(sessions):
    """Four sessions on a LocalCluster of 2 workers: two good, one with a missing frame, one with a bad
    session.json."""
    root, ref, _ = sessions
    good = [shutil.copytree(ref, root / name) for name in ("good_a", "good_b")]
    missing = shutil.copytree(ref, root / "missing_frame")
    (missing / "view_002" / "003.png").unlink()
    bad = shutil.copytree(ref, root / "bad_json")
    (bad / "session.json").write_text('{"schema": "rangekit.session/1", "views": 3}')
    lines = []
    res = process_sessions([good[0], missing, good[1], bad], ProcessOptions(report=False, truth=False), workers=2,
                           progress=lambda msg, *counts: lines.append(msg))
    return res, good, missing, bad, lines


@pytest.mark.slow     # the LocalCluster run behind these two tests: 17 s; make test-slow (CI) runs them
def test_two_sessions_on_a_local_cluster_give_the_bytes_of_serial_processing(sessions, local_batch):
    _, _, serial = sessions
    res, good, _, _, lines = local_batch
    by_folder = {o.folder: o for o in res.sessions}
    for folder in good:
        assert by_folder[folder].ok, by_folder[folder].error
        assert by_folder[folder].views_decoded == N_VIEWS and by_folder[folder].views_cached == 0
        for name in OUTPUTS:
            assert (folder / name).read_bytes() == serial[name], f"{folder.name}/{name} differs from serial"
        assert f"{folder}: done" in " ".join(lines)
    # progress: a line per view decoded
    assert sum("/view_" in line for line in lines) >= 2 * N_VIEWS


@pytest.mark.slow
def test_a_failing_session_is_reported_by_name_while_the_others_finish(local_batch):
    res, good, missing, bad, lines = local_batch
    assert [o.folder for o in res.sessions] == [good[0], missing, good[1], bad]   # in the order given
    assert [o.folder for o in res.failed] == [missing, bad]
    failed = {o.folder: o.error for o in res.failed}
    assert "view_002" in failed[missing] and "003.png" in failed[missing] and "missing" in failed[missing]
    assert "session.json" in failed[bad]
    assert not (missing / "mesh.ply").exists() and all((g / "mesh.ply").is_file() for g in good)
    assert any(str(missing) in line and "failed" in line for line in lines)


def test_the_session_task_takes_its_views_from_the_memo_as_read_from_their_caches(sessions, tmp_path):
    """The DASK placement's memo (rangekit.app.process.view_cache.ViewCaches, what finish_session_task hands the
    runner): the views the view tasks wrote, each read from its cache only when the decode stage takes it and
    announced then; the outputs are serial processing's bytes. A frame changed after its view task ran is found
    as the view is taken (its frames checked, as every cached view's are)."""
    from rangekit.app import events as ev
    from rangekit.app.process.view_cache import ViewCaches
    from rangekit.app.runner import Memo, Plan
    from rangekit.app.scan.scan import process_placed
    from rangekit.errors import FileFormatError

    root, _, serial = sessions
    options = ProcessOptions(report=False)

    def written(name):   # the serial session's views, cached, its outputs removed (as after the view tasks)
        folder = shutil.copytree(root / "serial", tmp_path / name)
        for out in (*OUTPUTS, "summary.json"):
            (folder / out).unlink(missing_ok=True)
        return folder, ViewCaches(folder, range(N_VIEWS), options.method, options.table_margin, options.max_motion)

    folder, caches = written("good")
    seen = []
    process_placed(folder, options, plan=Plan.LOCAL, memo=Memo(decoded=caches, announced=False), on_event=seen.append)
    assert len(caches) == 0                     # every view taken from the memo
    assert [e.index for e in seen if isinstance(e, ev.ViewDecoded)] == list(range(N_VIEWS))
    for name in OUTPUTS:
        assert (folder / name).read_bytes() == serial[name], name
    folder, caches = written("changed")
    frame = folder / "view_001" / "003.png"
    frame.write_bytes(frame.read_bytes() + b"\0")
    with pytest.raises(FileFormatError, match="003.png"):
        process_placed(folder, options, plan=Plan.LOCAL, memo=Memo(decoded=caches, announced=False))


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_an_unreachable_scheduler_is_a_clear_error_within_10_s(two_unprocessed, capsys):
    ref, other = two_unprocessed
    address = f"tcp://127.0.0.1:{_free_port()}"   # nothing listens there
    t0 = time.monotonic()
    with pytest.raises(SchedulerUnreachable, match=address):
        process_sessions([ref], scheduler=address, timeout=2)
    capsys.readouterr()
    assert main(["process", str(ref), str(other), "--scheduler", address]) == 1
    err = capsys.readouterr().err
    assert address in err and "dask scheduler" in err
    assert time.monotonic() - t0 < 10 + 2   # the CLI's 5 s timeout and the library call's 2 s


def test_process_options_are_checked_before_any_work(two_unprocessed, capsys):
    ref, other = two_unprocessed
    for args, expected in ((["--scheduler", "nowhere"], "--scheduler"), (["--workers", "0"], "--workers")):
        with pytest.raises(SystemExit) as e:
            main(["process", str(ref), str(ref), *args])
        assert e.value.code == 2 and expected in capsys.readouterr().err
    assert main(["process", str(ref), "--workers", "2"]) == 2              # one session: no Dask, no workers
    assert main(["process", str(ref), str(ref)]) == 2                      # the same folder twice
    assert main(["process", str(ref), str(other), "--scheduler", "tcp://127.0.0.1:1",
                 "--workers", "2"]) == 2


def _spawn(args: list[str]) -> subprocess.Popen:
    env = {**os.environ, **WORKER_ENV, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, "-m", *args], env=env, stdout=subprocess.DEVNULL,
                            stderr=subprocess.DEVNULL, start_new_session=True)


class _CacheWrites(threading.Thread):
    """Every distinct (inode, mtime) of each view's cloud.json seen while it runs: one per cache write
    (written atomically: a new file each time)."""

    def __init__(self, folders):
        super().__init__(daemon=True)
        self.files = [f / f"view_{i:03d}" / "cloud.json" for f in folders for i in range(N_VIEWS)]
        self.seen = {p: set() for p in self.files}
        self.stop = threading.Event()

    def run(self):
        while not self.stop.is_set():
            self.poll()
            time.sleep(0.005)

    def poll(self):
        for p in self.files:
            try:
                st = os.stat(p)
            except OSError:
                continue
            self.seen[p].add((st.st_ino, st.st_mtime_ns))

    def written(self) -> int:
        return sum(bool(s) for s in self.seen.values())


@pytest.mark.slow
def test_a_worker_killed_in_the_middle_loses_nothing_and_decodes_no_view_twice(sessions):
    from distributed import Client

    root, ref, serial = sessions
    folders = [shutil.copytree(ref, root / f"cluster_{k}") for k in range(3)]
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    procs = [_spawn(["distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", str(port),
                     "--dashboard-address", ":0", "--no-dashboard"])]
    try:
        procs += [_spawn(["distributed.cli.dask_worker", address, "--nthreads", "1", "--no-nanny",
                          "--no-dashboard", "--host", "127.0.0.1"]) for _ in range(2)]
        with Client(address, timeout="30s") as client:
            client.wait_for_workers(2, timeout=60)
        writes = _CacheWrites(folders)
        writes.start()
        out = {}
        batch = threading.Thread(target=lambda: out.update(res=process_sessions(
            folders, ProcessOptions(report=False, truth=False), scheduler=address)), daemon=True)
        batch.start()
        deadline = time.monotonic() + 120
        while writes.written() < 1 and time.monotonic() < deadline:   # the first view is cached: kill a worker
            time.sleep(0.01)
        victim = procs[1]
        os.killpg(victim.pid, signal.SIGKILL)
        victim.wait(10)
        killed_after = writes.written()
        batch.join(300)
        writes.stop.set()
        writes.join()
        writes.poll()
    finally:
        for p in procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGTERM)
        for p in procs:
            try:
                p.wait(15)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
    res = out["res"]
    assert killed_after < 3 * N_VIEWS, "the worker was killed after all the views were decoded"
    assert not res.failed, [o.error for o in res.failed]
    for folder in folders:
        for name in OUTPUTS:
            assert (folder / name).read_bytes() == serial[name], f"{folder.name}/{name}"
    # nothing lost (every view cached), nothing done twice (each cache written once)
    assert {p: len(s) for p, s in writes.seen.items()} == {p: 1 for p in writes.files}
    assert all(json.loads(p.read_text())["points"] > 0 for p in writes.files)


@pytest.mark.slow     # a LocalCluster and three small sessions: about 15 s
def test_sessions_are_finished_in_groups_one_a_worker(sessions):
    """With 2 workers, sessions a and b form the first group: neither session task exists until every view of
    both is decoded (so both start together); c's waits for c's views; the pairs are tasks of their own. Read
    from the scheduler's own log."""
    import logging

    from distributed import LocalCluster

    root, ref, serial = sessions
    folders = [shutil.copytree(ref, root / f"group_{name}") for name in "abc"]
    environ = dict(os.environ)   # Dask's nanny leaves its pre-spawn variables in this process: put it back
    try:
        with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                          dashboard_address=None, env=dict(WORKER_ENV), silence_logs=logging.ERROR) as cluster:
            res = process_sessions(folders, ProcessOptions(report=False, truth=False), scheduler=cluster.scheduler_address)
            log = list(cluster.scheduler.transition_log)
    finally:
        os.environ.clear()
        os.environ.update(environ)
    assert not res.failed, [o.error for o in res.failed]
    assert all((f / "mesh.ply").read_bytes() == serial["mesh.ply"] for f in folders)
    first_seen, decoded = {}, {}
    for t in log:
        first_seen.setdefault(t.key, t.timestamp)
        if t.key.startswith("decode-") and t.finish == "memory":
            decoded[t.key] = t.timestamp
    views = {f.name: [ts for k, ts in decoded.items() if k.startswith(f"decode-{f.name}-")] for f in folders}
    session = {f.name: next(ts for k, ts in first_seen.items() if k.startswith(f"session-{f.name}-")) for f in folders}
    assert all(len(v) == N_VIEWS for v in views.values())
    group = max(views["group_a"] + views["group_b"])
    assert session["group_a"] >= group and session["group_b"] >= group
    assert session["group_c"] >= max(views["group_c"])
    # each view pair's registration ran as a task of its own (rangekit.app.batch.pairs), none redone in a session
    pairs = {t.key for t in log if t.key.startswith("refine_pair-") and t.finish == "memory"}
    assert len(pairs) >= 3 * (N_VIEWS - 1), len(pairs)


def test_local_workers_keep_their_pages_and_quiet_housekeeping():
    """The local cluster's workers start with one malloc arena that is never trimmed (rangekit._runtime.memory then
    keeps freed pages for the next task) and Dask's periodic housekeeping slowed down (rangekit.app.batch.sessions)."""
    from rangekit.app.batch.sessions import QUIET_DASK, WORKER_MALLOC, _client

    def inside():
        import dask

        import rangekit._runtime.memory

        return ({k: os.environ.get(k) for k in WORKER_MALLOC}, rangekit._runtime.memory._ONE_ARENA,
                {k: dask.config.get(k) for k in QUIET_DASK})

    os.environ["MALLOC_TRIM_THRESHOLD_"] = "65536"   # as an earlier Dask cluster in this process leaves it
    try:
        with _client("local", 1, 5) as client:
            (found,) = client.run(inside).values()
        assert os.environ["MALLOC_TRIM_THRESHOLD_"] == "65536" and "MALLOC_ARENA_MAX" not in os.environ  # put back
    finally:
        os.environ.pop("MALLOC_TRIM_THRESHOLD_")
    assert found == (WORKER_MALLOC, True, QUIET_DASK)


def test_the_cluster_recipe_in_docs_matches_the_local_workers():
    """docs/scale.md's worker command and Dask configuration for a cluster give what the local cluster sets."""
    import dask
    import yaml

    from rangekit.app.batch.sessions import QUIET_DASK, WORKER_MALLOC

    page = (ROOT / "docs" / "scale.md").read_text()
    assert all(f"{k}={v}" in page for k, v in WORKER_MALLOC.items())
    block = page[page.index("    distributed:\n"):].split("\n\n")[0]
    config = yaml.safe_load("\n".join(line[4:] for line in block.splitlines()))
    assert {k: dask.config.get(k, config=config) for k in QUIET_DASK} == QUIET_DASK


@pytest.mark.slow
def test_pairs_shipped_away_and_back_give_the_bits_of_serial_registration():
    """A round's pairs pickled as a cluster would ship them, refined with k-d trees built anew: the poses of
    serial registration, bit for bit; the Dask mapper outside any cluster redoes the round here, the same."""
    import pickle

    import numpy as np

    from rangekit.app.batch.pairs import dask_pair_mapper
    from rangekit.registration.multiview import MultiViewOptions, register_views
    from rangekit.registration.pair_refine import refine_pair
    from rangekit.sim.writers.scans import perturb_poses, turntable_scans

    scans = turntable_scans(n_views=6, noise=0.0002, resolution=(320, 240), rng=3)
    prior = perturb_poses(scans.T_world_view, max_angle=np.radians(1), max_translation=0.005 * scans.diag, rng=2)
    options = MultiViewOptions(turntable=True)
    shipped = []

    def away(jobs, clouds):
        jobs, clouds = pickle.loads(pickle.dumps((list(jobs), list(clouds))))
        shipped.append(len(jobs))
        return [refine_pair(job, clouds[job.i], clouds[job.j]) for job in jobs]

    said = []
    serial = register_views(scans.clouds, init_T_world_view=prior, options=options)
    remote = register_views(scans.clouds, init_T_world_view=prior, options=options, map_pairs=away)
    here = register_views(scans.clouds, init_T_world_view=prior, options=options,
                          map_pairs=dask_pair_mapper(progress=said.append))
    assert shipped and sum(shipped) >= 6
    assert np.array_equal(serial.T_world_view, remote.T_world_view)
    assert np.array_equal(serial.T_world_view, here.T_world_view)
    assert [(e.i, e.j, e.rmse) for e in serial.edges] == [(e.i, e.j, e.rmse) for e in remote.edges]
    assert said and "redone here" in said[0]
