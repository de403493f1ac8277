"""Where a pytest run's memory goes: each test's growth of its worker, and the processes at the machine's peak.

    python benchmarks/harness/suite_memory.py [--top N] -- python -m pytest -q -m "not slow" -n 2

The command is run with this file loaded as a pytest plugin (``-p suite_memory``): as each test starts, its worker's
high-water mark is reset (``/proc/self/clear_refs``), and as it ends the worker's resident size at the start and
its peak during the test are recorded (the test's own process only; a child it starts is not in it). Beside the
run, every second: the machine's used memory above its start (``MemTotal - MemAvailable``, as
:mod:`tree_peak` measures it) and each process of the tree's proportional set size (PSS: a shared page divided
among the processes that map it, so the sizes add up). Printed: the ``N`` tests that grew their worker most, and the
tree's processes at the second the machine's used memory peaked. Linux only.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil

#: The folder the plugin writes its records into (one file per worker), set by :func:`main`.
RECORDS_ENV = "RANGEKIT_SUITE_MEMORY_DIR"


# -------------------------------------------------------------- the pytest plugin (in each worker)
def _status() -> dict:
    with open("/proc/self/status") as f:
        return {line.split(":")[0]: int(line.split()[1]) * 1024 for line in f if line.startswith(("VmHWM", "VmRSS"))}


def pytest_runtest_logstart(nodeid, location):
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")     # the high-water mark back to the resident size now
    pytest_runtest_logstart.rss = _status()["VmRSS"]


def pytest_runtest_logfinish(nodeid, location):
    folder = os.environ.get(RECORDS_ENV)
    if not folder:
        return
    status = _status()
    record = {"test": nodeid, "start": getattr(pytest_runtest_logstart, "rss", 0), "peak": status["VmHWM"]}
    with open(Path(folder) / f"{os.environ.get('PYTEST_XDIST_WORKER', 'main')}.jsonl", "a") as f:
        f.write(json.dumps(record) + "\n")


# -------------------------------------------------------------- the run
def _machine_used() -> int:
    with open("/proc/meminfo") as f:
        info = {line.split(":")[0]: int(line.split()[1]) * 1024 for line in f}
    return info["MemTotal"] - info["MemAvailable"]


def _tree_pss(root: psutil.Process) -> list[tuple[int, str]]:
    """(PSS bytes, the command line's start) of ``root`` and each descendant now."""
    out = []
    try:
        procs = [root] + root.children(recursive=True)
    except psutil.NoSuchProcess:
        return out
    for p in procs:
        try:
            out.append((p.memory_full_info().pss, " ".join(p.cmdline())[:100]))
        except (psutil.NoSuchProcess, psutil.AccessDenied):
            pass
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--top", type=int, default=20, help="tests to list (default 20)")
    ap.add_argument("command", nargs=argparse.REMAINDER)
    args = ap.parse_args()
    cmd = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not cmd:
        ap.error("give the pytest command after --")
    records = Path(tempfile.mkdtemp(prefix="suite-memory-"))
    here = str(Path(__file__).resolve().parent)
    env = dict(os.environ, **{RECORDS_ENV: str(records),
                              "PYTHONPATH": os.pathsep.join(p for p in (here, os.environ.get("PYTHONPATH")) if p)})
    used0 = _machine_used()
    proc = subprocess.Popen([*cmd, "-p", "suite_memory"], env=env)
    root, peak = psutil.Process(proc.pid), (-1, [])
    while proc.poll() is None:
        used = _machine_used() - used0
        if used > peak[0]:
            peak = (used, _tree_pss(root))
        time.sleep(1.0)
    tests = [json.loads(line) for f in records.glob("*.jsonl") for line in f.read_text().splitlines()]
    tests.sort(key=lambda r: r["peak"] - r["start"], reverse=True)
    print(f"\nexit {proc.returncode}; the machine's used memory at most {peak[0] / 1e9:.2f} GB above its start "
          f"(sampled every second); then, PSS of each process of the tree:")
    for pss, line in sorted(peak[1], reverse=True):
        print(f"  {pss / 1e9:5.2f} GB  {line}")
    print(f"the {args.top} tests that grew their worker most (resident size at the start -> peak during the test):")
    for r in tests[:args.top]:
        print(f"  +{(r['peak'] - r['start']) / 1e9:.2f} GB ({r['start'] / 1e9:.2f} -> {r['peak'] / 1e9:.2f})  {r['test']}")
    return proc.returncode


if __name__ == "__main__":
    sys.exit(main())
