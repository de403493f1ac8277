"""The surroundings a command runs in (issue 34, internal errors from the environment): a deleted working
folder, numba's thread variable, an ASCII-only output encoding, a low address-space limit, and Ctrl-C
while the libraries load. Each ends with one line and exit 1, 2 or 130: no traceback, no crash by signal,
no "internal error". Real child processes (rangekit._runtime.environment acts before anything loads).
"""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from support.cli_runs import ROOT, assert_error, cli_process


def _env(**extra) -> dict:
    env = dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""), **extra)
    env.pop("RANGEKIT_DEBUG", None)
    return env


@pytest.mark.parametrize("value", ["0", "abc", "-3", ""])
def test_a_bad_numba_thread_count_is_named(tmp_path, value):
    run = cli_process("reconstruct", tmp_path, "--out", tmp_path / "c.ply", env=_env(NUMBA_NUM_THREADS=value))
    assert_error(run, 2, f"NUMBA_NUM_THREADS={value!r}", "whole number of threads >= 1")


def test_a_deleted_working_folder_is_named(tmp_path):
    gone = tmp_path / "gone"
    gone.mkdir()
    # The child starts in the folder, which is removed before it runs (as a shell whose folder was deleted).
    code = ("import os, sys, runpy; os.rmdir(os.getcwd()); sys.argv = ['rangekit', 'reconstruct', 'cap', '--out', "
            "'c.ply']; runpy.run_module('rangekit', run_name='__main__')")
    proc = subprocess.run([sys.executable, "-c", code], cwd=gone, env=_env(), capture_output=True, text=True,
                          stdin=subprocess.DEVNULL, timeout=120)
    assert proc.returncode == 2, proc.stderr
    assert proc.stderr.strip().splitlines()[-1].startswith("rangekit: error: the working folder no longer exists")
    assert "Traceback" not in proc.stderr


def test_an_ascii_output_encoding_escapes_a_non_ascii_path(tmp_path):
    np.savetxt(tmp_path / "pts\u00e9.xyz", np.random.default_rng(0).normal(size=(300, 3)) * 0.05)
    run = cli_process("mesh", tmp_path / "pts\u00e9.xyz", "--out", tmp_path / "m\u00e9.ply",
                      env=_env(PYTHONIOENCODING="ascii"))
    assert run.code == 0, run.err
    assert "m\\xe9.ply" in run.out and "Traceback" not in run.err
    assert (tmp_path / "m\u00e9.ply").is_file()


@pytest.mark.parametrize("megabytes", [400, 600, 1200])
def test_a_low_address_space_limit_is_one_line(tmp_path, megabytes):
    """600 MB crashed with SIGSEGV, 400 and 1200 MB failed to map a library: each is now named."""
    limit = megabytes << 20

    def low_limit():
        resource.setrlimit(resource.RLIMIT_AS, (limit, resource.getrlimit(resource.RLIMIT_AS)[1]))

    run = cli_process("sim", "render", "--object", "sphere", "--out", tmp_path / "cap", preexec_fn=low_limit)
    line = assert_error(run, 1, "ulimit -v", f"{megabytes} MB")
    assert "internal error" not in line


@pytest.mark.parametrize("delay", [0.05, 0.4, 1.0])
def test_ctrl_c_while_the_libraries_load_exits_130(tmp_path, delay):
    """SIGINT at several moments of start-up (numpy, OpenCV, Open3D, numba load one after another)."""
    proc = subprocess.Popen([sys.executable, "-m", "rangekit", "sim", "render", "--object", "sphere", "--out",
                             str(tmp_path / "cap")], env=_env(), stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))  # as from a terminal
    time.sleep(delay)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=120)
    if proc.returncode == 0:
        # Seen once in a dozen runs at 0.05 s: the SIGINT was lost before any rangekit code ran (the
        # interpreter's own start-up) and the command ran to its end. Reported, not passed.
        pytest.skip(f"the SIGINT at {delay} s was lost before rangekit started; the command finished")
    # 130, or a death by SIGINT (-2) after the line: a shell shows both as $? = 130. A SIGINT landing while
    # Open3D's extension loads is handed back by it after rangekit has handled it (about 1 run in 8 at 0.4 s).
    if "/rangekit/" not in err and "rangekit: interrupted" not in err:
        # The SIGINT landed in the interpreter's own start-up (site, runpy), before any file of rangekit ran:
        # a death by the signal, or Python's own traceback, nothing rangekit can handle. Reported, not passed.
        pytest.skip(f"the SIGINT at {delay} s landed in Python's start-up, before rangekit's first line")
    assert proc.returncode in (130, -signal.SIGINT), (proc.returncode, err)
    assert err.strip().splitlines()[-1] == "rangekit: interrupted", err
    assert "Traceback" not in err and "initialization failed" not in err


def test_the_start_up_ctrl_c_handler_hands_over_to_the_command_lines(monkeypatch):
    """``python -m rangekit`` installs a Ctrl-C handler while the package imports (rangekit/__init__.py);
    the command line must replace it, or a Ctrl-C mid-scan would skip the 'Continue with' hint (CI's
    slow scan tests caught this)."""
    import rangekit
    from rangekit._runtime.environment import watching_interrupts

    def early(signum, frame):   # stands in for the start-up handler
        raise AssertionError("the start-up handler is still installed")

    monkeypatch.setattr(rangekit, "_interrupted_while_starting", early, raising=False)
    before = signal.signal(signal.SIGINT, early)
    try:
        with watching_interrupts():
            during = signal.getsignal(signal.SIGINT)
        after = signal.getsignal(signal.SIGINT)
    finally:
        signal.signal(signal.SIGINT, before)
    assert during not in (early, signal.default_int_handler, signal.SIG_IGN)
    assert after is signal.default_int_handler
