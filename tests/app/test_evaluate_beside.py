"""The evaluator's mesh-independent part runs beside the registration (rangekit.app.process.evaluate.prepared_beside):
the same call, on another thread, while the block runs; its error raised when the block ends."""

from __future__ import annotations

import threading

import pytest

from rangekit.app.process.evaluate import prepared_beside


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
