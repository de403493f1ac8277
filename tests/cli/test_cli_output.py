"""What the command line prints: progress on stderr (a tqdm bar with an ETA on a terminal, plain
lines elsewhere), results on stdout, -q/-v on every command, and output extensions refused before any work."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

from rangekit.cli import build_parser, main

ROOT = Path(__file__).resolve().parents[2]
ENV = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONUNBUFFERED": "1"}
# The quickest real acquisition: 2 views of one De Bruijn frame each (a per-frame bar of 2 steps).
SCAN = ["scan", "--views", "2", "--patterns", "debruijn", "--object", "plane", "--no-process"]
CONTROL = ("\r", "\x1b")


def _rangekit(*args: str) -> list[str]:
    return [sys.executable, "-m", "rangekit", *args]


def test_piped_scan_prints_plain_lines_results_on_stdout_progress_on_stderr(tmp_path):
    """``rangekit scan ... 2>FILE | cat``: no carriage return or escape code in either stream."""
    err = tmp_path / "stderr.txt"
    cmd = " ".join(_rangekit(*SCAN, "--out", str(tmp_path / "s"))) + f" 2>{err} | cat"
    run = subprocess.run(cmd, shell=True, capture_output=True, text=True, env=ENV, cwd=tmp_path, timeout=300)
    out, log = run.stdout, err.read_text()
    assert run.returncode == 0, log
    assert not any(c in out or c in log for c in CONTROL), (out, log)
    assert "view 1/2: frame 1/1" in log and "view 2/2 done" in log        # progress per frame and view
    assert "view" not in out.split("acquired")[0] and out.startswith("acquired 2 views x 1 frames")


def test_a_terminal_gets_a_bar_with_an_eta(tmp_path):
    """stderr on a pseudo-terminal: the tqdm bar, redrawn with carriage returns, with its ETA."""
    master, slave = os.openpty()
    proc = subprocess.Popen(_rangekit(*SCAN, "--out", str(tmp_path / "s")), stdout=subprocess.PIPE, stderr=slave,
                            env=ENV, cwd=tmp_path)
    os.close(slave)
    chunks = []
    while True:
        try:
            data = os.read(master, 4096)
        except OSError:     # EIO: the child closed the terminal
            break
        if not data:
            break
        chunks.append(data)
    os.close(master)
    out = proc.stdout.read().decode()
    assert proc.wait(timeout=300) == 0
    tty = b"".join(chunks).decode(errors="replace")
    assert "\r" in tty and "ETA" in tty and "%|" in tty and "2/2" in tty, tty
    assert "view 2/2 done" in tty                   # a message printed above the bar
    assert out.startswith("acquired 2 views") and not any(c in out for c in CONTROL)


@pytest.mark.slow
def test_quiet_prints_only_the_final_result_line(tmp_path):
    run = subprocess.run(_rangekit("-q", *SCAN, "--out", str(tmp_path / "s")), capture_output=True, text=True,
                         env=ENV, cwd=tmp_path, timeout=300)
    assert run.returncode == 0 and run.stderr == ""
    assert run.stdout.count("\n") == 1 and run.stdout.startswith("acquired 2 views x 1 frames"), run.stdout
    bad = subprocess.run(_rangekit(*SCAN, "-q", "--out", str(tmp_path / "s")), capture_output=True, text=True,
                         env=ENV, cwd=tmp_path, timeout=300)   # the folder exists now: an error, still shown
    assert bad.returncode == 2 and bad.stdout == "" and bad.stderr.startswith("rangekit: error: --out")


@pytest.mark.parametrize("argv", [["-q", "rig", "init"], ["rig", "init", "-q"], ["--quiet", "sim", "objects"],
                                  ["-v", "mesh", "c.ply", "--out", "m.ply"], ["mesh", "c.ply", "--out", "m.ply", "-v"],
                                  ["process", "DIR", "--verbose"], ["rig", "import", "f.yaml", "-q"]])
def test_verbosity_options_are_accepted_before_and_after_every_command(argv):
    args = build_parser().parse_args(argv)
    assert getattr(args, "quiet", False) or getattr(args, "verbose", False)


def test_every_command_takes_the_verbosity_options():
    from rangekit.cli.run import _leaf_parsers

    for p in _leaf_parsers(build_parser()):
        if p._defaults.get("func") is not None:
            assert {"-q", "-v", "--quiet", "--verbose"} <= set(p._option_string_actions), p.prog


def test_quiet_and_verbose_together_are_a_usage_error(capsys):
    assert main(["-q", "rig", "init", "-v"]) == 2
    assert "rangekit: error: -v/--verbose and -q/--quiet: expected one of them, found both" in capsys.readouterr().err


@pytest.mark.parametrize("argv, option, expected, found", [
    (["mesh", "{missing}.ply", "--out", "{out}.pcd"], "--out", ".ply, .obj, .stl, .glb", "'.pcd'"),
    (["reconstruct", "{missing}", "--out", "{out}.stl"], "--out", ".ply, .pcd, .xyz, .npy, .e57", "'.stl'"),
    (["decode", "{missing}", "--pattern", "graycode", "--projector", "64x64", "--out", "{out}"], "--out", ".npz",
     "no extension"),
    (["render", "{missing}.ply", "--out", "{out}.jpg"], "--out", ".png", "'.jpg'"),
    (["calibrate", "--rig", "sim", "--out", "{out}.yaml"], "--out", ".json", "'.yaml'"),
    (["rig", "import", "{missing}.yaml", "--out", "{out}.yaml"], "--out", ".json", "'.yaml'"),
])
def test_a_bad_output_extension_is_refused_before_any_work(tmp_path, capsys, argv, option, expected, found):
    """Exit 2 naming the option, the expected and the found extension; the input is never read (it does not
    exist: reading it first would be exit 1)."""
    argv = [a.format(missing=tmp_path / "missing", out=tmp_path / "out") for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert f"rangekit: error: {option} {tmp_path / 'out'}" in err and f"({expected})" in err and found in err, err
    assert not list(tmp_path.iterdir())
