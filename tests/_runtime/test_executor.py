"""The executor (rangekit/_runtime/executor.py): one configured worker count, 0 = automatic; calls placed here, on
a thread or in a child behind one interface; an ordered map that holds at most ``workers`` results. (The job's
event bus: tests/app/test_bus.py.)"""

from __future__ import annotations

import os
import threading

import pytest

from rangekit._runtime.executor import WORKERS_ENV, Where, ordered_map, start, worker_count
from rangekit.errors import ConfigError


def test_the_worker_count_is_one_configured_number(monkeypatch):
    monkeypatch.delenv(WORKERS_ENV, raising=False)
    assert worker_count() == len(os.sched_getaffinity(0)) == worker_count(0)
    assert worker_count(3) == 3
    monkeypatch.setenv(WORKERS_ENV, "5")
    assert worker_count() == 5 and worker_count(1) == 1
    monkeypatch.setenv(WORKERS_ENV, "many")
    with pytest.raises(ConfigError, match=WORKERS_ENV):
        worker_count()
    for bad in (-1, 1.5, True):
        with pytest.raises(ConfigError, match="workers"):
            worker_count(bad)


def _square(x: int) -> int:
    return x * x


@pytest.mark.parametrize("where", [Where.HERE, Where.THREAD, Where.CHILD])
def test_a_call_runs_where_placed_behind_one_interface(where):
    with start(where, _square, 7) as call:
        assert call.result() == 49
    with start(where, _square, "x") as call:
        with pytest.raises((TypeError, RuntimeError)):
            call.result()


@pytest.mark.parametrize("workers", [1, 2, 3])
def test_the_ordered_map_keeps_the_order_and_holds_at_most_workers_results(workers):
    running, most = [0], [0]
    lock = threading.Lock()

    def slow(k: int) -> int:
        with lock:
            running[0] += 1
            most[0] = max(most[0], running[0])
        try:
            return k
        finally:
            with lock:
                running[0] -= 1

    taken = []
    for k in ordered_map(slow, range(10), workers=workers):
        taken.append(k)
    assert taken == list(range(10)) and most[0] <= workers
