"""Run a command and print its wall seconds, CPU seconds and the peak memory of its whole process tree.

    python benchmarks/harness/tree_peak.py [--label NAME] -- COMMAND [ARG ...]

``/usr/bin/time``'s maximum resident size is that of the largest single process; ``rangekit process``
runs its Poisson in a child process and ``rangekit process S1 S2 ...`` runs Dask workers, so their
memory is the sum over the tree. Here the tree (the command and every descendant) is sampled every
50 ms with psutil and the largest sum of resident sizes is printed, with the wall time and the user +
system CPU of the command and every descendant it waited for (``os.wait4``'s resource usage).
The command's own output goes to this process's stdout/stderr.

A sum of resident sizes counts the shared libraries (Open3D, OpenCV, numpy: about 250 MB) once per process, so a
tree of many Python processes (``pytest -n 2`` with its command-line children) sums far above what the machine
gives it. The last figure printed is that instead: the peak of the machine's used memory (``MemTotal -
MemAvailable``, /proc/meminfo) above what it was when the command started (on a machine doing nothing else).
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import threading
import time

import psutil


def _tree_rss(root: psutil.Process) -> int:
    """Bytes resident in ``root`` and its descendants now (processes that vanish count 0)."""
    total = 0
    try:
        procs = [root] + root.children(recursive=True)
    except psutil.NoSuchProcess:
        return 0
    for p in procs:
        try:
            total += p.memory_info().rss
        except psutil.NoSuchProcess:
            pass
    return total


_LINE = re.compile(r": ([\d.]+) s wall, ([\d.]+) CPU-s .* peak of the process tree ([\d.]+) GB, exit (-?\d+)")


def _machine_used() -> int:
    """Bytes of the machine's memory in use now (MemTotal - MemAvailable; 0 where /proc/meminfo is missing)."""
    try:
        with open("/proc/meminfo") as f:
            info = {line.split(":")[0]: int(line.split()[1]) * 1024 for line in f}
    except (OSError, ValueError, IndexError):
        return 0
    return info.get("MemTotal", 0) - info.get("MemAvailable", 0)


def measured(command: list[str], **popen) -> dict:
    """Run ``command`` under this script (``popen``: subprocess.run's keywords, e.g. ``cwd``, ``env``):
    {wall_s, cpu_s, peak_gb, exit, stderr}. Its own output is dropped but for stderr."""
    done = subprocess.run([sys.executable, __file__, "--", *command], stdout=subprocess.DEVNULL,
                          stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL, **popen)
    m = _LINE.search(done.stderr.splitlines()[-1] if done.stderr else "")
    if not m:
        raise SystemExit(f"{' '.join(command)}: no timing line in its output:\n{done.stderr[-2000:]}")
    return {"wall_s": float(m[1]), "cpu_s": float(m[2]), "peak_gb": float(m[3]), "exit": int(m[4]),
            "stderr": done.stderr}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--label", default="run")
    ap.add_argument("command", nargs=argparse.REMAINDER)
    args = ap.parse_args()
    cmd = args.command[1:] if args.command[:1] == ["--"] else args.command
    if not cmd:
        ap.error("give the command after --")
    t0, used0 = time.perf_counter(), _machine_used()
    proc = subprocess.Popen(cmd)
    root, peak, done = psutil.Process(proc.pid), [0, 0], threading.Event()

    def sample() -> None:
        while not done.is_set():
            peak[0] = max(peak[0], _tree_rss(root))
            peak[1] = max(peak[1], _machine_used() - used0)
            time.sleep(0.05)

    sampler = threading.Thread(target=sample, daemon=True)
    sampler.start()
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    done.set()
    sampler.join()
    code = os.waitstatus_to_exitcode(status)
    print(f"{args.label}: {wall:.1f} s wall, {usage.ru_utime + usage.ru_stime:.1f} CPU-s "
          f"({usage.ru_utime:.1f} user + {usage.ru_stime:.1f} sys), peak of the process tree "
          f"{peak[0] / 1e9:.2f} GB, exit {code}; the machine's used memory {peak[1] / 1e9:.2f} GB above its start",
          file=sys.stderr)
    return code


if __name__ == "__main__":
    sys.exit(main())
