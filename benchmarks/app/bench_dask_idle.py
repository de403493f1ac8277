"""What an idle local Dask cluster of 2 workers costs, with Dask's defaults and with rangekit's
``QUIET_DASK`` (many sessions on Dask, docs/scale.md).

    PYTHONPATH=. python benchmarks/app/bench_dask_idle.py [--seconds 30]

For each setting a ``LocalCluster`` of 2 one-thread worker processes is started on 127.0.0.1 (as
``rangekit process S1 S2 ...`` starts it, without tasks), left 3 s to settle, then the CPU seconds (user +
sys, psutil) of this process and every descendant (the scheduler runs here; nannies and workers are
children) are read before and after ``--seconds`` of idling. Printed per setting: CPU-s per 100 s.
"""

from __future__ import annotations

import argparse
import logging
import sys
import time
from pathlib import Path

import psutil

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))  # the repo (this is benchmarks/app/bench_dask_idle.py)


def tree_cpu() -> float:
    """CPU seconds (user + sys) of this process and its descendants so far."""
    total = 0.0
    me = psutil.Process()
    for p in [me] + me.children(recursive=True):
        try:
            t = p.cpu_times()
        except psutil.NoSuchProcess:
            continue
        total += t.user + t.system
    return total


def idle_cost(config: dict, seconds: float) -> float:
    """CPU-s per 100 s of an idle 2-worker local cluster under ``config``."""
    import dask
    from distributed import Client, LocalCluster

    with dask.config.set(config):
        with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                          dashboard_address=None, silence_logs=logging.ERROR) as cluster, Client(cluster):
            time.sleep(3)
            before = tree_cpu()
            time.sleep(seconds)
            return (tree_cpu() - before) / seconds * 100


def main() -> None:
    from rangekit.app.batch.sessions import QUIET_DASK

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seconds", type=float, default=30.0)
    args = ap.parse_args()
    for label, config in (("Dask's defaults", {}), ("rangekit's QUIET_DASK", QUIET_DASK)):
        print(f"{label}: {idle_cost(config, args.seconds):.1f} CPU-s per 100 s idle (2 workers)", flush=True)


if __name__ == "__main__":
    main()
