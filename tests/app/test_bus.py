"""The job's event bus (rangekit/app/bus.py): subscribers on its own thread, in order, a subscriber's error raised
to the job."""

from __future__ import annotations

import threading

import pytest

from rangekit.app.bus import EventBus


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
