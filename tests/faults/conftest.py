"""Fixtures of the fault-injection tests (``cli`` and ``reference_session`` are the suite's, tests/conftest.py).

``mount_tmpfs(size, read_only=False)`` mounts a real small tmpfs (a full or read-only disk; skips where
mounting is not permitted). ``budget(text)`` sets RANGEKIT_MEMORY_BUDGET for one test (4G unless
set); ``no_pixels`` fails a test that decodes any image (refusals must come from the headers).
"""

from __future__ import annotations

import subprocess
import tempfile
from pathlib import Path

import cv2
import pytest

from rangekit.budget import ENV_VAR




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

    def imdecode(*args, **kwargs):
        raise AssertionError("pixels were decoded: cv2.imdecode")
    monkeypatch.setattr(cv2, "imread", imread)
    monkeypatch.setattr(cv2, "imdecode", imdecode)
