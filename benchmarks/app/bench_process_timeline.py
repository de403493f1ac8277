"""``rangekit process`` of a session as a timeline: when each long call starts and ends, on which thread, and its CPU.

    PYTHONPATH=. .venv/bin/python benchmarks/app/bench_process_timeline.py SESSION

Runs :func:`rangekit.app.scan.scan.process` (one BLAS thread, as the command line) on SESSION, which it changes
(caches, outputs): give it a fresh copy of a session made by ``rangekit scan --out S --no-process``. Each of the
calls below is wrapped; when it returns, one line: its start and end (wall seconds from this script's start), its
duration, the CPU seconds this process (user + sys, every thread) and its waited-for children spent meanwhile,
and the thread it ran on. Calls beside each other overlap in time; their CPU figures then count each other's
threads too. Issue 36 read the critical path from it (docs/benchmarks.md).
"""

from __future__ import annotations

import resource
import sys
import threading
import time
from pathlib import Path

T0 = time.perf_counter()

import rangekit.app.process.fuse as fuse  # noqa: E402
import rangekit.app.process.process as process_module  # noqa: E402
import rangekit.sim.truth.evaluate as evaluate  # noqa: E402
import rangekit.sim.truth.view_errors as view_errors  # noqa: E402
import rangekit.surface.watertight as watertight  # noqa: E402

#: (module, function) pairs timed.
CALLS = ((process_module, "decode"), (process_module, "register"), (process_module, "measure_views"),
         (process_module, "measure_closed"), (process_module, "_report"), (evaluate, "truth_samples"),
         (evaluate, "mesh_accuracy"), (view_errors, "view_errors"), (watertight, "make_watertight"),
         (fuse, "save_one"), (fuse, "save_cloud"), (process_module, "evaluate_observed"))


def _cpu() -> tuple[float, float]:
    me, children = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return me.ru_utime + me.ru_stime, children.ru_utime + children.ru_stime


def _timed(module, name: str) -> None:
    plain = getattr(module, name)
    label = f"{module.__name__.rsplit('.', 1)[-1]}.{name}"

    def run(*args, **kwargs):
        w0, (c0, k0) = time.perf_counter(), _cpu()
        try:
            return plain(*args, **kwargs)
        finally:
            w1, (c1, k1) = time.perf_counter(), _cpu()
            print(f"{w0 - T0:7.2f} -> {w1 - T0:7.2f}  {w1 - w0:6.2f} s  CPU {c1 - c0:6.2f}  children {k1 - k0:5.2f}  "
                  f"[{threading.current_thread().name}] {label}", flush=True)

    setattr(module, name, run)


def main() -> int:
    if len(sys.argv) != 2:
        print(__doc__)
        return 2
    for module, name in CALLS:
        _timed(module, name)
    from rangekit._runtime.threads import one_blas_thread
    from rangekit.app.scan.scan import process

    with one_blas_thread():
        process(Path(sys.argv[1]))
    cpu, children = _cpu()
    print(f"total {time.perf_counter() - T0:.2f} s wall, {cpu:.2f} CPU-s in this process, {children:.2f} in its children")
    return 0


if __name__ == "__main__":
    sys.exit(main())
