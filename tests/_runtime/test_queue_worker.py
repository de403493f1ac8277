"""The queue worker (rangekit/_runtime/queue_worker.py), the STREAMING placement's thread: items in order on a
thread of lower priority, none started while held, the queued ones handled by finish and dropped by stop, the
first error kept (the worker ends). Synchronised with events, not timed."""

from __future__ import annotations

import os
import threading

from rangekit._runtime.queue_worker import QueueWorker


def _counted(held: list, seen: list, entries: list | None = None):
    """A context (a context manager factory, as ``QueueWorker(context=)`` takes) that counts the blocks open in
    ``held[0]``, appends ("exit", count left) to ``seen`` as each ends and each entering thread's name to
    ``entries``."""
    from contextlib import contextmanager

    lock = threading.Lock()

    @contextmanager
    def counted():
        with lock:
            held[0] += 1
            if entries is not None:
                entries.append(threading.current_thread().name)
        try:
            yield
        finally:
            with lock:
                held[0] -= 1
                seen.append(("exit", held[0]))

    return counted


def test_items_run_in_order_on_a_lower_priority_thread_and_what_is_left_at_finish_on_the_caller():
    """Until finish the items run on the worker at its niceness; from finish on, the worker ends after the item it
    is handling and the rest run on the caller's thread at the caller's priority (issue 51: at niceness 10 beside
    other programs the worker got no CPU once the capture was over)."""
    seen, where = [], []
    started, gate = threading.Event(), threading.Event()

    def fn(item):
        seen.append(item)
        where.append((item, threading.current_thread().name,
                      os.getpriority(os.PRIO_PROCESS, threading.get_native_id())))
        if item == 2:
            started.set()
            gate.wait(30)

    before = os.getpriority(os.PRIO_PROCESS, 0)
    worker = QueueWorker(fn, name="rk-test-worker", nice=min(19, before + 5))
    for k in range(3):
        worker.put(k)
    assert started.wait(30)       # item 2 is being handled on the worker
    for k in range(3, 6):
        worker.put(k)

    def let_go():                 # item 2 ends once finish has begun, so 3.. are the caller's
        while not worker._handing_over:
            threading.Event().wait(0.005)
        gate.set()

    threading.Thread(target=let_go).start()
    worker.finish()
    lower, caller = min(19, before + 5), threading.current_thread().name
    assert seen == [0, 1, 2, 3, 4, 5] and worker.error is None and worker.paused == 0
    assert where == [(0, "rk-test-worker", lower), (1, "rk-test-worker", lower), (2, "rk-test-worker", lower),
                     (3, caller, before), (4, caller, before), (5, caller, before)]
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


def test_the_context_holds_from_the_workers_first_item_through_the_items_finish_hands_to_the_caller():
    """QueueWorker(context=): the worker's loop runs inside it, and finish enters it on the caller's thread before
    the worker ends, so it is never left between the two (the scan's memory-reuse block: the last view, decoded on
    the caller's thread, reuses the worker's pages, rangekit.app.runner.StreamingWorker)."""
    held, seen, entries = [0], [], []
    counted = _counted(held, seen, entries)

    started, gate = threading.Event(), threading.Event()

    def fn(item):
        seen.append((item, held[0]))
        if item == 0:
            started.set()
            gate.wait(30)

    worker = QueueWorker(fn, name="rk-test-context", context=counted)
    worker.put(0)
    assert started.wait(30)
    worker.put(1)

    def let_go():
        while not worker._handing_over:
            threading.Event().wait(0.005)
        gate.set()

    threading.Thread(target=let_go).start()
    worker.finish()
    caller = threading.current_thread().name
    assert sorted(entries) == sorted(["rk-test-context", caller])
    # item 0 inside the worker's block; the worker's block ends with the caller's already entered (1 left), item 1
    # inside the caller's, then it ends: the count never reaches 0 in between
    assert seen == [(0, 1), ("exit", 1), (1, 1), ("exit", 0)]


def test_after_hand_over_no_item_starts_on_the_worker_and_finish_handles_them_on_the_caller_in_its_context():
    """hand_over (the scan's last view acquired): the item being handled goes on, the next ones (queued before or
    after) wait for finish and run on the caller's thread at its priority, in order; the worker's idle work stops
    and its context is held until finish has entered the caller's (the memory-reuse block never ends between)."""
    held, seen, idle = [0], [], []
    counted = _counted(held, seen)

    started, gate = threading.Event(), threading.Event()

    def fn(item):
        seen.append((item, threading.current_thread().name,
                     os.getpriority(os.PRIO_PROCESS, threading.get_native_id()), held[0]))
        if item == 0:
            started.set()
            gate.wait(30)

    def idle_work():
        idle.append(worker._handing_over)
        return 0.01

    before = os.getpriority(os.PRIO_PROCESS, 0)
    lower = min(19, before + 5)
    worker = QueueWorker(fn, name="rk-test-hand-over", nice=lower, context=counted, idle=idle_work)
    worker.put(0)
    assert started.wait(30)
    worker.put(1)              # queued before the hand-over
    worker.hand_over()
    worker.put(2)              # after it
    gate.set()
    for _ in range(300):       # the worker has ended item 0 and takes 1 and 2 for the caller, running none
        if len(worker._handed) == 2:
            break
        threading.Event().wait(0.01)
    assert [s[0] for s in seen] == [0] and worker._thread.is_alive() and held[0] == 1
    worker.finish()
    caller = threading.current_thread().name
    # the worker's block ends with the caller's entered (1 left): the count never reaches 0 in between
    assert seen == [(0, "rk-test-hand-over", lower, 1), ("exit", 1), (1, caller, before, 1), (2, caller, before, 1),
                    ("exit", 0)], seen
    assert not any(idle) and held[0] == 0 and worker.error is None
