"""QuietWindows: the capture's waits told to the work beside it (rangekit.app.acquire.quiet), with real threads."""

import threading

from rangekit.app.acquire.quiet import QuietWindows


def test_no_acquisition_no_wait_and_an_open_window_lets_work_start():
    quiet = QuietWindows()
    assert quiet.wait(0.06, timeout_s=0.0)              # nothing opened yet: at once
    quiet.open(10.0)
    assert quiet.wait(0.06, timeout_s=0.0)              # 10 s left
    quiet.close()                                        # the capture woke: not now
    assert not quiet.wait(0.06, timeout_s=0.05)
    quiet.end()
    assert quiet.wait(0.06, timeout_s=0.0)              # the acquisition is over


def test_a_waiter_goes_when_the_next_window_opens_even_if_windows_are_short():
    quiet = QuietWindows()
    quiet.open(0.02)
    quiet.close()                                        # windows of 20 ms: shorter than the 60 ms asked
    seen, started = [], threading.Event()

    def work():
        started.set()
        ok = quiet.wait(0.06, timeout_s=30.0)
        with quiet._changed:
            seen.append((ok, quiet._until > 0))              # a window was open when it went
    t = threading.Thread(target=work)
    t.start()
    started.wait()
    while t.is_alive():                                  # the capture's rhythm: 20 ms asleep, 10 ms awake
        quiet.open(0.02)
        t.join(0.02)
        quiet.close()
        t.join(0.01)
    assert seen == [(True, True)]                        # went in a fresh window, as good as it gets


def test_the_end_releases_a_waiter():
    quiet = QuietWindows()
    quiet.open(0.1)
    quiet.close()
    out = []
    t = threading.Thread(target=lambda: out.append(quiet.wait(0.06, timeout_s=30.0)))
    t.start()
    quiet.end()
    t.join(30)
    assert out == [True]


def test_a_window_until_closed_for_a_turntable_move():
    quiet = QuietWindows()
    quiet.open(None)                                     # a move of unknown length: open until closed
    assert quiet.wait(5.0, timeout_s=0.0)
    quiet.close()
    assert not quiet.wait(0.06, timeout_s=0.05)
