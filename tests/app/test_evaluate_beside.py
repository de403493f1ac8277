"""The evaluator's mesh-independent part runs beside the registration, where the job runner places it
(rangekit.app.runner: Work.TRUTH_PREPARE, a thread in every plan): the same call, on another thread, while the block
runs; its error raised when its result is taken; without an evaluator, no thread."""

from __future__ import annotations

import threading

import pytest

from contextlib import contextmanager

from rangekit._runtime.executor import Where
from rangekit.app.runner import PLACEMENTS, Plan, Runner, Work


@contextmanager
def prepared_beside(evaluate, angles):
    """As rangekit.app.process.process runs it around the register stage."""
    runner = Runner(plan=Plan.LOCAL)
    with (runner.beside(Work.TRUTH_PREPARE, evaluate.prepare, angles) if evaluate is not None else
          runner.beside(Work.TRUTH_PREPARE, lambda: threading.current_thread(), where=Where.HERE)) as truth:
        yield
        truth.result()


def test_the_truth_is_prepared_on_a_thread_in_every_plan():
    assert {PLACEMENTS[Work.TRUTH_PREPARE][plan] for plan in Plan} == {Where.THREAD}


class _Recorder:
    def __init__(self, fail: bool = False) -> None:
        self.calls, self.fail = [], fail
        self.started = threading.Event()
        self.release = threading.Event()

    def prepare(self, angles, views=None):
        self.started.set()
        self.release.wait(10)
        self.calls.append((list(angles), views, threading.current_thread() is threading.main_thread()))
        if self.fail:
            raise RuntimeError("the truth failed")


def test_prepare_runs_on_another_thread_while_the_block_runs():
    ev = _Recorder()
    with prepared_beside(ev, [0.0, 0.5]):
        assert ev.started.wait(10)     # running while the block has not ended
        assert ev.calls == []
        ev.release.set()
    assert ev.calls == [([0.0, 0.5], None, False)]


def test_its_error_is_raised_when_the_block_ends():
    ev = _Recorder(fail=True)
    ev.release.set()
    with pytest.raises(RuntimeError, match="the truth failed"):
        with prepared_beside(ev, [0.0]):
            pass


def test_no_evaluator_no_thread():
    with prepared_beside(None, [0.0]):
        pass
    with Runner().beside(Work.TRUTH_PREPARE, threading.current_thread, where=Where.HERE) as here:
        assert here.result() is threading.current_thread()
