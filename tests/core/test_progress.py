"""Progress output: a bar on a terminal, plain lines elsewhere."""

import io
import logging

from rangekit.progress import Console, StageTimer, call_progress


def test_plain_lines_when_not_a_terminal():
    buf = io.StringIO()
    con = Console(buf)  # StringIO is not a tty
    assert not con.tty
    con("view 1/3 done", 1, 3)
    con("registering")
    con("view 3/3 done", 3, 3)
    assert buf.getvalue() == "view 1/3 done\nregistering\nview 3/3 done\n"


def test_bar_on_a_terminal_has_an_eta_and_messages_go_above_it():
    buf = io.StringIO()
    con = Console(buf, tty=True, width=10)
    con("decoding", 1, 4)
    con("decoding", 2, 4)
    con("a message")          # printed above the open bar
    con("decoding", 4, 4)     # complete: the bar is closed
    out = buf.getvalue()
    assert "\r" in out and "ETA" in out and "2/4" in out and "4/4" in out and "a message\n" in out
    assert out.rstrip().endswith("ETA 00:00]")


def test_off_a_terminal_every_view_of_a_scan_has_its_line():
    """12 views decoded: 12 lines (a per-tenth throttle hid the 7th, which read as a lost view); up to
    EVERY_STEP_UP_TO steps each is a line, a longer count one a tenth."""
    from rangekit.progress import EVERY_STEP_UP_TO

    for n in (12, 13, 99, EVERY_STEP_UP_TO):
        buf = io.StringIO()
        con = Console(buf, tty=False)
        for k in range(1, n + 1):
            con(f"decoded view_{k - 1:03d}", k, n)
        assert buf.getvalue().splitlines() == [f"decoded view_{k:03d}" for k in range(n)]
    buf = io.StringIO()
    con = Console(buf, tty=False)
    for k in range(1, EVERY_STEP_UP_TO + 2):
        con(f"step {k}", k, EVERY_STEP_UP_TO + 1)
    assert len(buf.getvalue().splitlines()) == 11


def test_plain_lines_at_each_tenth_and_nothing_when_quiet():
    buf = io.StringIO()
    con = Console(buf, tty=False)
    for i in range(1, 401):
        con(f"frame {i}/400", i, 400)
    lines = buf.getvalue().splitlines()
    assert lines == [f"frame {i}/400" for i in (1, 40, 80, 120, 160, 200, 240, 280, 320, 360, 400)]
    quiet = io.StringIO()
    Console(quiet, tty=True, level=logging.WARNING)("decoding", 1, 2)
    Console(quiet, level=logging.WARNING)("a message")
    assert quiet.getvalue() == ""
    verbose = io.StringIO()
    con = Console(verbose, level=logging.DEBUG)
    for i in range(1, 401):
        con(f"frame {i}/400", i, 400)
    assert len(verbose.getvalue().splitlines()) == 400


def test_call_progress_accepts_plain_callables_and_none():
    seen = []
    call_progress(seen.append, "one line only", 1, 2)   # a one-argument callable still works
    call_progress(None, "ignored", 1, 2)
    call_progress(lambda m, d=None, t=None: seen.append((m, d, t)), "counted", 1, 2)
    assert seen == ["one line only", ("counted", 1, 2)]


def test_stage_timer_adds_up_repeated_stages():
    t = StageTimer()
    with t.stage("a"):
        pass
    with t.stage("a"):
        pass
    with t.stage("b"):
        pass
    assert list(t.seconds) == ["a", "b"] and all(v >= 0 for v in t.seconds.values())
