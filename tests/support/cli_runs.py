"""Running the command line in tests; the in-process ``cli`` fixture is in tests/conftest.py.

``cli_process(*args)`` runs ``rangekit ARGS`` as a real child process for what needs one (signals, closed
streams, another user, resource limits). ``assert_error(run, code, *mentions)``: the exit code, no
traceback, the last line ``rangekit: error: ...`` mentioning each of ``mentions`` (the file or option, the
expected and the found value). Import them with ``from cli_runs import assert_error, cli_process``.
"""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


@dataclass(frozen=True)
class Run:
    code: int
    out: str
    err: str


def cli_process(*args, timeout: float = 300, **kwargs) -> Run:
    """``python -m rangekit ARGS`` as a child process, no standard input, stdout and stderr captured (pass
    ``stdout=`` to send it elsewhere); other kwargs go to subprocess.run."""
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    env.pop("RANGEKIT_DEBUG", None)
    kwargs.setdefault("stdin", subprocess.DEVNULL)
    kwargs.setdefault("stdout", subprocess.PIPE)
    proc = subprocess.run([sys.executable, "-m", "rangekit", *[str(a) for a in args]], stderr=subprocess.PIPE,
                          text=True, errors="backslashreplace", timeout=timeout, env=kwargs.pop("env", env), **kwargs)
    return Run(proc.returncode, proc.stdout or "", proc.stderr)


def assert_error(run: Run, code: int, *mentions) -> str:
    """The run failed with ``code``, no traceback, and its last stderr line is a rangekit error naming each
    of ``mentions``; returns that line."""
    assert run.code == code, f"exit {run.code}, expected {code}\nstdout: {run.out[-2000:]}\nstderr: {run.err[-2000:]}"
    assert "Traceback" not in run.err, run.err
    assert "internal error" not in run.err, run.err
    lines = run.err.strip().splitlines()
    assert lines and lines[-1].startswith("rangekit: error: "), run.err
    for m in mentions:
        assert str(m) in lines[-1], f"{m!r} not in {lines[-1]!r}"
    return lines[-1]
