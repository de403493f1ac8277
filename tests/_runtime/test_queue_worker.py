"""The queue worker (rangekit/_runtime/queue_worker.py), the STREAMING placement's thread: items in order on a
thread of lower priority, none started while held, the queued ones handled by finish and dropped by stop, the
first error kept (the worker ends). Synchronised with events, not timed."""

from __future__ import annotations

import os
import threading

from rangekit._runtime.queue_worker import QueueWorker


def test_items_are_handled_in_order_on_a_lower_priority_thread():
    seen, where = [], []

    def fn(item):
        seen.append(item)
        where.append((threading.current_thread().name, os.getpriority(os.PRIO_PROCESS, threading.get_native_id())))

    before = os.getpriority(os.PRIO_PROCESS, 0)
    worker = QueueWorker(fn, name="rk-test-worker", nice=min(19, before + 5))
    for k in range(5):
        worker.put(k)
    worker.finish()
    assert seen == [0, 1, 2, 3, 4] and worker.error is None and worker.paused == 0
    assert set(where) == {("rk-test-worker", min(19, before + 5))}
    assert os.getpriority(os.PRIO_PROCESS, 0) == before   # the caller's own priority is untouched


def test_no_item_starts_while_held_and_finish_lets_the_rest_go():
    started, gate = threading.Event(), threading.Event()
    seen = []

    def fn(item):
        seen.append(item)
        if item == 0:
            started.set()
            gate.wait(30)

    worker = QueueWorker(fn, name="rk-test-held")
    worker.put(0)
    assert started.wait(30)
    worker.hold()          # item 0 is being handled: it goes on; item 1 waits
    worker.put(1)
    gate.set()
    for _ in range(3000):  # the worker takes item 1 and waits for the release
        if worker.paused:
            break
        threading.Event().wait(0.01)
    assert seen == [0] and worker.paused == 1
    worker.release()
    worker.hold()
    worker.put(2)
    worker.finish()        # the end releases what is held
    assert seen == [0, 1, 2] and worker.error is None


def test_stop_drops_the_queued_items():
    started, gate = threading.Event(), threading.Event()
    seen = []

    def fn(item):
        seen.append(item)
        started.set()
        gate.wait(30)

    worker = QueueWorker(fn, name="rk-test-stop")
    worker.put(0)
    worker.put(1)
    assert started.wait(30)
    threading.Timer(0.05, gate.set).start()
    worker.stop()
    assert seen == [0]


def test_the_first_error_is_kept_and_ends_the_worker():
    seen = []

    def fn(item):
        seen.append(item)
        if item == 1:
            raise ValueError("bad item")

    worker = QueueWorker(fn, name="rk-test-error")
    for k in range(3):
        worker.put(k)
    worker.finish()
    assert seen == [0, 1] and isinstance(worker.error, ValueError)
    worker.stop()          # after the end: returns at once
