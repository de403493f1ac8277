"""Sessions nobody can corrupt, what a run does to one: resume options that differ from the
session, the lock (one process per session), process outputs written as a set, a full disk mid-scan.
Each test works on a copy of the small reference session (tests/support/sessions.py).
"""

from __future__ import annotations

import os
import resource
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from support.cli_runs import ROOT, assert_error, cli_process
from support.sessions import copy_session, frames, journal, no_leftovers, snapshot
from support.small_rigs import small_rig
from rangekit.app.acquire.acquire import acquire
from rangekit.coded.patterns import make_pattern_spec
from rangekit.formats.sessions.session import ScanPlan, Session
from rangekit.formats.sessions.check import verify_views
from rangekit.sim import SimRig, default_scene


# -- 5. resume options that differ from the session ----------------------------------------------------

@pytest.mark.parametrize("option, value, recorded", [
    ("--views", "5", "4"), ("--object", "sphere", "'lumpy'"), ("--seed", "2", "1"),
    ("--patterns", "hybrid", "'graycode'"), ("--rig", "my_rig.json", "'sim'"),
])
def test_resume_with_an_option_that_differs_from_the_session_stops(cli, reference_session, tmp_path, option, value,
                                                                   recorded):
    d = copy_session(reference_session, tmp_path / "s", pending=(3,))
    before, log = snapshot(d), journal(d)
    assert_error(cli("scan", "--resume", d, "--no-process", option, value), 2, option, value, recorded, str(d))
    assert snapshot(d) == before and not (d / "view_003").exists() and journal(d).startswith(log)


def test_resume_with_the_sessions_own_options_goes_on(cli, reference_session, tmp_path):
    d = copy_session(reference_session, tmp_path / "s", pending=(3,))
    run = cli("scan", "--resume", d, "--no-process", "--views", "4", "--object", "lumpy", "--seed", "1",
              "--patterns", "graycode", "--rig", "sim")
    assert run.code == 0, run.err
    assert frames(d) == frames(reference_session)
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


def test_a_second_process_of_a_session_in_use_stops_at_once(cli, reference_session, tmp_path):
    d = copy_session(reference_session, tmp_path / "s", pending=(2, 3))
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
    # The first one finished undisturbed: the same frames as the uninterrupted reference_session.
    assert frames(d) == frames(reference_session)
    no_leftovers(d)


def test_a_stale_lock_of_a_dead_process_is_taken_over(cli, reference_session, tmp_path):
    d = copy_session(reference_session, tmp_path / "s", pending=(3,))
    dead = subprocess.Popen(["true"])
    dead.wait()
    (d / ".lock").write_text(f"{dead.pid}\n")
    run = cli("scan", "--resume", d, "--no-process")
    assert run.code == 0, run.err
    assert (d / ".lock").read_text().strip() == str(os.getpid())
    assert frames(d) == frames(reference_session)


def test_the_lock_is_held_for_the_whole_block_and_released(tmp_path):
    from rangekit.formats.sessions.lock import SessionLocked, session_lock

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

@pytest.mark.slow     # 14 s (two processings); make test-slow (CI) runs it
def test_a_process_that_fails_between_outputs_leaves_no_summary(cli, reference_session, tmp_path):
    d = copy_session(reference_session, tmp_path / "s")
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

def test_a_full_disk_mid_scan_says_how_to_resume_and_the_resume_completes(cli, reference_session, tmp_path):
    d = copy_session(reference_session, tmp_path / "s", pending=(3,))
    before, log = snapshot(d), journal(d)
    limit = min(p.stat().st_size for p in (d / "view_000").glob("*.png")) // 2
    assert limit > 1000   # the lock file and the first bytes fit, a frame does not

    def small_files():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)   # writes past the limit fail with EFBIG
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))

    run = cli_process("scan", "--resume", d, "--no-process", preexec_fn=small_files)
    assert_error(run, 1, "view 3", "000.png", "File too large", f"rangekit scan --resume {d}")
    assert snapshot(d) == before and journal(d).startswith(log)   # finished views intact, nothing half-written
    no_leftovers(d)
    assert cli("scan", "--resume", d, "--no-process").code == 0
    assert frames(d) == frames(reference_session)


@pytest.fixture
def small_disk(mount_tmpfs):
    return mount_tmpfs("16m")


def test_a_disk_that_fills_up_mid_scan_keeps_every_finished_view(cli, reference_session, small_disk, monkeypatch):
    import rangekit.cli._common as common

    monkeypatch.setattr(common, "MIN_FREE_BYTES", 0)   # the disk is small from the start
    d = copy_session(reference_session, small_disk / "s", pending=(1, 2, 3))
    view_bytes = sum(p.stat().st_size for p in (reference_session / "view_001").iterdir())
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
    assert frames(d) == frames(reference_session)
