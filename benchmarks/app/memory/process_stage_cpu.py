"""CPU of ``rangekit process`` stage by stage: the process's user and system seconds and minor page faults at each
stage's start and end (getrusage, every thread of this process; the Poisson child's as the children's), from the
runner's stage events.

    PYTHONPATH=<tree> python benchmarks/app/memory/process_stage_cpu.py SESSION

SESSION is processed in place: give a fresh copy of a simulated session (``cp -r``) to include the decode. Run it
with two trees' PYTHONPATH on two copies to compare them (issue 51: the decode stage's system time).
"""

from __future__ import annotations

import resource
import sys
import time


def main(folder: str) -> int:
    from rangekit.app.process.process import process_session
    from rangekit.app.scan.truth import session_evaluator
    from rangekit.formats.sessions.session import load_session

    t0 = time.perf_counter()

    def on_event(event) -> None:
        name = type(event).__name__
        if name in ("StageStarted", "StageFinished"):
            r, c = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
            print(f"{time.perf_counter() - t0:6.2f} s {name:14s} {str(getattr(event, 'stage', '')):9s} "
                  f"user {r.ru_utime:6.2f} sys {r.ru_stime:6.2f} minflt {r.ru_minflt:8d} | "
                  f"children user {c.ru_utime:5.2f} sys {c.ru_stime:5.2f}", flush=True)

    session = load_session(folder)
    process_session(session, evaluate=session_evaluator(session), on_event=on_event)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1]))
