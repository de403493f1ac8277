"""``rangekit process`` of a session, each stage's wall and CPU seconds and memory (for its speed targets).

    PYTHONPATH=. .venv/bin/python benchmarks/app/bench_process_stages.py SESSION [--no-report] [--serial-evaluation]

Runs :func:`rangekit.app.scan.scan.process` (the work of ``rangekit process``, one BLAS thread as the CLI)
on SESSION, which it changes (caches, outputs): give it a fresh copy of a session made by ``rangekit scan
--out S --no-process`` for a run without the view cache. Prints, per stage, the resident and the peak
memory at its start and end; the stage times the summary records (wall) and the CPU seconds (user + sys
of every thread) spent inside each stage; the wall seconds of the evaluator's two mesh-independent parts
(the truth's samples and visibility, the per-view errors); then the process's total CPU, wall and peak.
Stages nest: the evaluator's mesh-independent half runs inside "fuse", beside the fusion thread, and is
counted in both. ``--serial-evaluation`` hides the evaluator's ``prepare`` from processing, so all of the
evaluation runs after the fusion (the memory/wall trade-off in docs/benchmarks.md).
"""

from __future__ import annotations

import resource
import sys
import time
from contextlib import contextmanager

import rangekit.progress as progress_module


def _mb(field: str) -> int:
    with open("/proc/self/status") as f:
        return int(f.read().split(field + ":")[1].split()[0]) // 1024


def _timed(module, name: str, seconds: dict):
    plain = getattr(module, name)

    def run(*args, **kwargs):
        w0 = time.perf_counter()
        try:
            return plain(*args, **kwargs)
        finally:
            seconds[name] = seconds.get(name, 0.0) + time.perf_counter() - w0

    setattr(module, name, run)


def main() -> int:
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    if len(args) != 1:
        print(__doc__)
        return 2
    cpu: dict[str, float] = {}
    plain = progress_module.StageTimer.stage

    @contextmanager
    def stage(self, name):
        print(f"start {name}: resident {_mb('VmRSS')} MB, peak {_mb('VmHWM')} MB", flush=True)
        c0 = time.process_time()
        with plain(self, name):
            yield
        cpu[name] = cpu.get(name, 0.0) + time.process_time() - c0
        print(f"end {name}: resident {_mb('VmRSS')} MB, peak {_mb('VmHWM')} MB", flush=True)

    progress_module.StageTimer.stage = stage
    import rangekit.app.scan.scan as scan_module
    from rangekit.app.process.options import ProcessOptions
    import rangekit.sim.truth.evaluate as evaluate_module
    import rangekit.sim.truth.view_errors as view_errors_module
    from rangekit._runtime.threads import one_blas_thread

    parts: dict[str, float] = {}
    _timed(evaluate_module, "truth_samples", parts)
    _timed(view_errors_module, "view_errors", parts)
    if "--serial-evaluation" in sys.argv:
        with_prepare = scan_module.session_evaluator

        class Serial:
            """The evaluator with nothing done beside the fusion: its preparation runs inside the first call."""

            def __init__(self, ev) -> None:
                self._ev = ev

            def prepare(self, angles, views=None) -> None:
                pass

            def __call__(self, mesh, angles, **kw):
                return self._ev(mesh, angles, **kw)

        def without_prepare(session):
            ev = with_prepare(session)
            return None if ev is None else Serial(ev)

        scan_module.session_evaluator = without_prepare
    c0, w0 = time.process_time(), time.perf_counter()
    with one_blas_thread():
        result = scan_module.process(args[0], ProcessOptions(report="--no-report" not in sys.argv))
    print("stage wall s:", {k: round(v, 1) for k, v in result.seconds.items()})
    print("stage CPU s: ", {k: round(v, 1) for k, v in cpu.items()})
    print("evaluator parts, wall s:", {k: round(v, 1) for k, v in parts.items()})
    print(f"total {time.process_time() - c0:.1f} CPU-s, {time.perf_counter() - w0:.1f} s wall, peak "
          f"{resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MB")
    return 0


if __name__ == "__main__":
    sys.exit(main())
