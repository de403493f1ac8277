"""Output paths are checked before any work; write failures, closed streams and full disks end in one
``rangekit: error:`` line and leave no half-written file."""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from support.cli_runs import Run, assert_error, cli_process

# Commands whose --out is a file, and whose --out is a folder (each with the other arguments it needs; the
# inputs need not exist: the output is checked first).
FILE_OUTPUTS = [
    ["decode", "caps", "--pattern", "graycode", "--projector", "64x32"],
    ["reconstruct", "caps"],
    ["mesh", "cloud.ply"],
    ["render", "mesh.ply"],
    ["calibrate"],
]
FOLDER_OUTPUTS = [
    ["sim", "render"],
    ["register", "a.ply", "b.ply"],
    ["tof", "raw"],
    ["stereo", "l.png", "r.png", "--rig", "rig.json"],
    ["photometric", "ball"],
    ["scan"],
]


@pytest.mark.parametrize("args", FILE_OUTPUTS, ids=lambda a: a[0])
def test_an_existing_folder_where_a_file_is_expected(cli, tmp_path, args):
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "keep.txt").write_text("mine")
    run = cli(*args, "--out", tmp_path / "out")
    assert_error(run, 2, "--out", str(tmp_path / "out"), "expected a file name, found an existing folder")
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == ["keep.txt"]


@pytest.mark.parametrize("args", FOLDER_OUTPUTS, ids=lambda a: a[0])
def test_an_existing_file_where_a_folder_is_expected(cli, tmp_path, args):
    (tmp_path / "out").write_text("mine")
    run = cli(*args, "--out", tmp_path / "out")
    assert_error(run, 2, "--out", str(tmp_path / "out"), "expected a folder, found an existing file")
    assert (tmp_path / "out").read_text() == "mine"


def test_an_output_below_a_file_is_refused(cli, tmp_path):
    (tmp_path / "notes.txt").write_text("mine")
    run = cli("render", "mesh.ply", "--out", tmp_path / "notes.txt" / "x.png")
    assert_error(run, 2, "--out", "notes.txt", "is a file, not a folder")


def test_calibrate_refuses_an_existing_rig_file_before_calibrating(cli, tmp_path):
    (tmp_path / "rig.json").write_text("{}")
    run = cli("calibrate", "--out", tmp_path / "rig.json")
    assert_error(run, 2, "--out", "rig.json", "exists", "--force")
    assert (tmp_path / "rig.json").read_text() == "{}" and run.out == ""  # nothing was captured first


def test_a_read_only_output_folder_is_refused_before_any_work(cli, mount_tmpfs):
    ro = mount_tmpfs("1m", read_only=True)
    run = cli("calibrate", "--out", ro / "rig.json")
    assert_error(run, 2, "--out", str(ro), "not writable")
    run = cli("sim", "render", "--sensor", "stereo", "--size", "64x40", "--out", ro / "pair")
    assert_error(run, 2, "--out", "not writable")


def test_an_almost_full_disk_is_refused_before_any_work(cli, mount_tmpfs):
    small = mount_tmpfs("2m")
    run = cli("sim", "render", "--out", small / "cap")
    assert_error(run, 2, "--out", "MB free", "expected at least 64 MB")
    assert list(small.iterdir()) == []


def _file_size_limit(n_bytes: int):
    def limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (n_bytes, n_bytes))
    return limit


def test_a_write_that_fails_midway_names_the_file_and_leaves_no_partial_file(tmp_path):
    # Files are capped at 20 kB: the small files fit, the ground truth does not (EFBIG, as on a full disk).
    # A first run without the cap fills numba's on-disk cache: on a fresh clone the capped run would
    # otherwise fail writing a compiled kernel's cache file, not the command's own output.
    assert cli_process("sim", "render", "--sensor", "stereo", "--size", "160x100", "--out", tmp_path / "warm").code == 0
    out = tmp_path / "pair"
    run = cli_process("sim", "render", "--sensor", "stereo", "--size", "160x100", "--out", out,
                      preexec_fn=_file_size_limit(20_000))
    line = assert_error(run, 1, str(out), "no space left", "run the command again")
    assert "File too large" in line
    assert not list(out.rglob("*.tmp")) and not list(out.rglob(".*.tmp"))
    assert all(p.stat().st_size <= 20_000 for p in out.rglob("*") if p.is_file())


def test_rig_init_to_a_closed_stdout(tmp_path):
    # The shell closes descriptor 1 (`>&-`): Python starts with sys.stdout = None.
    proc = subprocess.run(f"'{sys.executable}' -m rangekit rig init >&-", shell=True, stderr=subprocess.PIPE,
                          stdin=subprocess.DEVNULL, text=True,
                          env=dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[2])))
    assert_error(Run(proc.returncode, "", proc.stderr), 1, "<stdout>", "standard output is closed", "rig.json")


def test_rig_init_into_a_pipe_closed_by_the_reader(tmp_path):
    read_end, write_end = os.pipe()
    os.close(read_end)
    try:
        run = cli_process("rig", "init", "--sim", stdout=write_end)
    finally:
        os.close(write_end)
    assert_error(run, 1, "standard output was closed")
    assert "Exception ignored" not in run.err


@pytest.mark.slow
def test_sigint_during_a_render_exits_130_and_leaves_no_partial_file(tmp_path):
    import time

    out = tmp_path / "cap"
    env = dict(os.environ, PYTHONPATH=str(Path(__file__).resolve().parents[2]))
    proc = subprocess.Popen([sys.executable, "-m", "rangekit", "sim", "render", "--out", str(out)],
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            env=env, preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    for line in proc.stderr:  # progress (stderr): interrupt while the frames are rendered and written (about 5 s)
        if line.startswith("rendering"):
            break
    time.sleep(1.0)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and err.strip().splitlines()[-1] == "rangekit: interrupted"
    assert not list(out.rglob("*.tmp"))
