"""Fixtures of the fault-injection tests (issue 16).

``cli(*args)`` runs ``rangekit ARGS`` in this process (fast: no interpreter start, no open3d import) and
returns a :class:`_faults.Run` (exit code, stdout, stderr); argparse's own exits are caught.
``mount_tmpfs(size, read_only=False)`` mounts a real small tmpfs (a full or read-only disk; skips where
mounting is not permitted). ``reference`` is the small finished session of tests/faults/_sessions.py,
made once per run; tests copy it. ``budget(text)`` sets RANGEKIT_MEMORY_BUDGET for one test (4G unless
set); ``no_pixels`` fails a test that decodes any image (refusals must come from the headers).
"""

from __future__ import annotations

import subprocess
import tempfile
from pathlib import Path

import cv2
import pytest

from _faults import Run
from rangekit.budget import ENV_VAR


@pytest.fixture
def cli(capsys):
    from rangekit.cli import main

    def run(*args) -> Run:
        capsys.readouterr()
        try:
            code = main([str(a) for a in args])
        except SystemExit as stop:  # argparse: --help, or a usage error
            code = stop.code if isinstance(stop.code, int) else 1
        captured = capsys.readouterr()
        return Run(code, captured.out, captured.err)

    return run


@pytest.fixture
def mount_tmpfs():
    """Mount a small tmpfs (root only; skips where mounting is not permitted) and unmount it afterwards."""
    mounted = []

    def mount(size: str, *, read_only: bool = False) -> Path:
        where = Path(tempfile.mkdtemp(prefix="rangekit-mount-"))
        opts = f"size={size}" + (",ro" if read_only else "")
        res = subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(where)], capture_output=True)
        if res.returncode != 0:
            where.rmdir()
            pytest.skip(f"cannot mount a tmpfs here: {res.stderr.decode().strip()}")
        mounted.append(where)
        return where

    yield mount
    for where in mounted:
        subprocess.run(["umount", str(where)], check=False)
        where.rmdir()


@pytest.fixture(scope="session")
def reference(tmp_path_factory) -> Path:
    """A finished simulated session as ``rangekit scan`` makes it (object lumpy, seed 1, graycode)."""
    from _sessions import make_reference

    return make_reference(tmp_path_factory.mktemp("reference") / "s")


@pytest.fixture
def budget(monkeypatch):
    """Set the memory budget (RANGEKIT_MEMORY_BUDGET) for one test, independent of this machine's memory."""
    def set_budget(text: str) -> None:
        monkeypatch.setenv(ENV_VAR, text)
    set_budget("4G")
    return set_budget


@pytest.fixture
def no_pixels(monkeypatch):
    """Fail the test if any image is decoded (the refusals must come from the headers)."""
    def imread(*args, **kwargs):
        raise AssertionError(f"pixels were read: cv2.imread{args}")
    monkeypatch.setattr(cv2, "imread", imread)
