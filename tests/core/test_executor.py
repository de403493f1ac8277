"""The executor (rangekit/_runtime/executor.py): one configured worker count, 0 = automatic; calls placed here, on
a thread or in a child behind one interface; an ordered map that holds at most ``workers`` results. And the job's
event bus (rangekit/app/bus.py): subscribers on its own thread, in order, a subscriber's error raised to the job."""

from __future__ import annotations

import os
import threading

import pytest

from rangekit._runtime.executor import WORKERS_ENV, Where, ordered_map, start, worker_count
from rangekit.app.bus import EventBus
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


def test_the_bus_hands_events_on_its_own_thread_in_order():
    seen, threads = [], set()

    def subscriber(event) -> None:
        seen.append(event)
        threads.add(threading.current_thread().name)

    with EventBus(subscriber) as bus:
        for k in range(100):
            bus.publish(k)
        bus.flush()
        assert seen == list(range(100))
    assert threads == {"rangekit-events"}


def test_a_subscriber_that_raises_stops_the_job_with_its_error():
    def fails(event) -> None:
        if event == 3:
            raise KeyError("subscriber")

    bus = EventBus(fails)
    with pytest.raises(KeyError, match="subscriber"):
        for k in range(1000):
            bus.publish(k)
            if k == 4:
                bus.flush()
    with pytest.raises(KeyError):
        bus.close()
