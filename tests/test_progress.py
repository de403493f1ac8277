"""Progress output: a bar on a terminal, plain lines elsewhere."""

import io

from rangekit.progress import Console, StageTimer, call_progress


def test_plain_lines_when_not_a_terminal():
    buf = io.StringIO()
    con = Console(buf)  # StringIO is not a tty
    assert not con.tty
    con("view 1/3 done", 1, 3)
    con("registering")
    con("view 3/3 done", 3, 3)
    assert buf.getvalue() == "view 1/3 done\nregistering\nview 3/3 done\n"


def test_bar_redraws_in_place_on_a_terminal_and_ends_its_line():
    buf = io.StringIO()
    con = Console(buf, tty=True, width=10)
    con("decoding", 1, 4)
    con("decoding", 2, 4)
    con("a message")          # ends the open bar line first
    con("decoding", 4, 4)     # complete: the bar line is ended
    out = buf.getvalue()
    assert out.count("\r") == 3 and "[##--------] 1/4 decoding" in out and "[#####-----] 2/4" in out
    assert "\na message\n" in out and out.endswith("[##########] 4/4 decoding\x1b[K\n")


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
