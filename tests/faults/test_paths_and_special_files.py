"""Paths and files a user's system can hold: a folder name that is not valid UTF-8 (Linux paths are bytes), a
FIFO or a device where a file is expected, a session lock file that is a symbolic link or a FIFO. Each is read
as bytes or refused by name: never a crash by signal, a hang, or a write through a link into another file."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from support.cli_runs import assert_error, cli_process
from support.sessions import copy_session


def _non_utf8(parent: Path, stem: bytes) -> Path:
    """A path under ``parent`` whose last part is the bytes ``stem`` (not valid UTF-8)."""
    return Path(os.fsdecode(os.fsencode(parent) + b"/" + stem))


@pytest.fixture(scope="module")
def capture(tmp_path_factory) -> Path:
    """A Gray-code capture folder of the simulator (its default rig: --size, which this once passed, was ignored
    for the projector sensor and is now refused, issue 48)."""
    out = tmp_path_factory.mktemp("capture") / "cap"
    run = cli_process("-q", "sim", "render", "--out", out, "--patterns", "graycode")
    assert run.code == 0, run.err
    return out


def test_a_capture_in_a_folder_named_with_non_utf8_bytes_is_read(capture, tmp_path):
    folder = _non_utf8(tmp_path, b"cap\xe9")
    shutil.copytree(capture, folder)
    out = _non_utf8(tmp_path, b"cloud\xff.ply")
    run = cli_process("reconstruct", folder, "--out", out, timeout=120)
    assert run.code == 0, run.err
    assert os.path.getsize(out) > 1000


def test_a_missing_image_under_a_non_utf8_name_is_one_line(capture, tmp_path):
    folder = _non_utf8(tmp_path, b"cap\xe9")
    shutil.copytree(capture, folder)
    os.remove(folder / "003.png")
    os.symlink("/nonexistent/frame.png", folder / "003.png")
    run = cli_process("reconstruct", folder, "--out", tmp_path / "c.ply", timeout=120)
    assert_error(run, 1, "003.png")


@pytest.mark.slow   # a whole session processed in a child process; make test-slow (CI) runs it
def test_a_session_in_a_non_utf8_folder_is_processed(reference_session, tmp_path):
    folder = copy_session(reference_session, _non_utf8(tmp_path, b"sess\xff"))
    run = cli_process("-q", "process", folder, "--no-report", timeout=300)
    assert run.code == 0, run.err
    assert (folder / "mesh.ply").is_file()


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_a_fifo_among_a_captures_frames_is_refused_not_waited_on(capture, tmp_path):
    folder = shutil.copytree(capture, tmp_path / "cap")
    os.remove(folder / "005.png")
    os.mkfifo(folder / "005.png")
    run = cli_process("reconstruct", folder, "--out", tmp_path / "c.ply", timeout=60)
    assert_error(run, 1, "005.png", "FIFO")
    assert not (tmp_path / "c.ply").exists()


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_a_fifo_as_a_sessions_frame_is_refused_by_name(reference_session, tmp_path):
    d = copy_session(reference_session, tmp_path / "s")
    os.remove(d / "view_002" / "007.png")
    os.mkfifo(d / "view_002" / "007.png")
    run = cli_process("process", d, "--no-report", timeout=120)
    assert_error(run, 1, "view_002", "007.png", "FIFO")
    assert not (d / "summary.json").exists()


def test_a_device_given_as_an_image_is_refused(tmp_path):
    if not os.path.exists("/dev/urandom"):
        pytest.skip("no /dev/urandom")
    folder = tmp_path / "cap"
    folder.mkdir()
    os.symlink("/dev/urandom", folder / "000.png")
    run = cli_process("decode", folder / "000.png", "--pattern", "white", "--out", tmp_path / "d.npz", timeout=60)
    assert_error(run, 1, "000.png", "device")


def test_a_lock_file_that_is_a_symlink_is_not_followed(reference_session, tmp_path):
    d = copy_session(reference_session, tmp_path / "s")
    precious = tmp_path / "precious.txt"
    precious.write_text("keep me\n")
    (d / ".lock").unlink(missing_ok=True)
    os.symlink(precious, d / ".lock")
    run = cli_process("process", d, "--no-report", timeout=120)
    assert_error(run, 1, ".lock", "symbolic link")
    assert precious.read_text() == "keep me\n"
    assert not (d / "summary.json").exists()


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
def test_a_lock_file_that_is_a_fifo_is_named(reference_session, tmp_path):
    d = copy_session(reference_session, tmp_path / "s")
    (d / ".lock").unlink(missing_ok=True)
    os.mkfifo(d / ".lock")
    run = cli_process("process", d, "--no-report", timeout=60)
    assert_error(run, 1, ".lock", "not a regular file")


# --------------------------------------------------------------------------- endless and special inputs
@pytest.mark.skipif(not os.path.exists("/dev/urandom"), reason="no /dev/urandom")
@pytest.mark.parametrize("name, command", [
    ("u.xyz", ["mesh", "{src}", "--out", "{tmp}/m.ply"]),
    ("u.ply", ["register", "{src}", "{src}", "--no-mesh", "--out", "{tmp}/r"]),
    ("u.obj", ["render", "{src}", "--out", "{tmp}/r.png"]),
    ("u.pcd", ["mesh", "{src}", "--out", "{tmp}/m.ply"]),
])
def test_an_endless_device_as_a_scan_or_mesh_is_refused_by_name(cli, tmp_path, name, command):
    """/dev/urandom linked as a cloud or mesh was read until killed."""
    src = tmp_path / name
    src.symlink_to("/dev/urandom")
    run = cli(*[a.format(src=src, tmp=tmp_path) for a in command])
    assert_error(run, 1, str(src), "is a device", "regular file")


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="no FIFOs here")
@pytest.mark.parametrize("name", ["f.xyz", "f.ply", "f.stl"])
def test_a_fifo_as_a_scan_or_mesh_is_refused_by_name(cli, tmp_path, name):
    src = tmp_path / name
    os.mkfifo(src)
    run = cli("render", src, "--out", tmp_path / "r.png")
    assert_error(run, 1, str(src), "FIFO")


@pytest.mark.slow
@pytest.mark.parametrize("sensor, size, command", [
    ("stereo", "160x100", ["stereo", "{src}/left.png", "{src}/right.png", "--rig", "{src}/rig.json", "--out", "{out}"]),
    ("tof", "64x48", ["tof", "{src}", "--out", "{out}"]),
])
def test_stereo_and_tof_read_folders_named_with_non_utf8_bytes(tmp_path, sensor, size, command):
    """stereo and tof were killed by SIGSEGV in the image read on such a path."""
    src = _non_utf8(tmp_path, b"cap\xe9")
    run = cli_process("-q", "sim", "render", "--sensor", sensor, "--size", size, "--out", tmp_path / "plain")
    assert run.code == 0, run.err
    shutil.copytree(tmp_path / "plain", src)
    out = _non_utf8(tmp_path, b"out\xff")
    run = cli_process(*[os.fsdecode(a).format(src=os.fsdecode(src), out=os.fsdecode(out)) for a in command], timeout=120)
    assert run.code == 0, run.err
    assert (out / "cloud.ply").is_file()
