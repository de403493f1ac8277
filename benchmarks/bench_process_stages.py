"""``rangekit process`` of a session with each stage's wall and CPU seconds (issue 20).

    PYTHONPATH=. .venv/bin/python benchmarks/bench_process_stages.py SESSION [--no-report]

Runs :func:`rangekit.app.scan.process_scan` (the work of ``rangekit process``, one BLAS thread as the CLI)
on SESSION, which it changes (caches, outputs): give it a fresh copy of a session made by ``rangekit scan
--out S --no-process`` for a run without the view cache. Prints the stage times the summary records (wall)
and the CPU seconds (user + sys of every thread) spent inside each stage, then the process's total CPU,
wall and peak memory. Stages nest: the evaluator's mesh-independent half runs inside "fuse", beside the
fusion thread, and is counted in both.
"""

from __future__ import annotations

import resource
import sys
import time
from contextlib import contextmanager

import rangekit.progress as progress_module


def main() -> int:
    if len(sys.argv) < 2:
        print(__doc__)
        return 2
    cpu: dict[str, float] = {}
    plain = progress_module.StageTimer.stage

    @contextmanager
    def stage(self, name):
        c0 = time.process_time()
        with plain(self, name):
            yield
        cpu[name] = cpu.get(name, 0.0) + time.process_time() - c0

    progress_module.StageTimer.stage = stage
    from rangekit.app.scan import process_scan
    from rangekit.threads import one_blas_thread

    c0, w0 = time.process_time(), time.perf_counter()
    with one_blas_thread():
        result = process_scan(sys.argv[1], report="--no-report" not in sys.argv)
    print("stage wall s:", {k: round(v, 1) for k, v in result.seconds.items()})
    print("stage CPU s: ", {k: round(v, 1) for k, v in cpu.items()})
    print(f"total {time.process_time() - c0:.1f} CPU-s, {time.perf_counter() - w0:.1f} s wall, peak "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
