"""A session's events.jsonl (issue 49, 2): a scan writes every event as a line as it runs, in this process or as a
child; the lines read back typed, in order; a resumed scan appends; a reader follows the file from an offset."""

from __future__ import annotations

import json
from collections import Counter
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import rangekit as rk
from rangekit.app import events as ev
from rangekit.formats.sessions.files import EVENTS_FILE
from rangekit.app.event_log import (EventLog, JobExited, LoggedCloud, LoggedError, from_json,
                                    read_events, to_json)
from rangekit.app.scan.options import ScanOptions
from rangekit.errors import FileFormatError


def _typed(folder: Path) -> list:
    return [e for e, _ in read_events(folder / EVENTS_FILE)]


def _same(written, read) -> bool:
    """``read`` (from the log) stands for ``written``: every field equal, a cloud by its count, a pose its numbers."""
    if type(written) is not type(read):
        return False
    for name, value in vars(written).items():
        got = getattr(read, name)
        if name == "cloud":
            ok = len(got) == len(value)
        elif name == "T_world_view":
            ok = np.array_equal(np.asarray(value, float), got)
        elif name == "error":
            ok = str(got) == " ".join(str(value).split()) or type(value).__name__
        elif name == "mesh":
            ok = (got.vertices, got.triangles) == (len(value.vertices), len(value.triangles))
        else:
            ok = got == value
        if not ok:
            return False
    return True


def test_every_event_type_goes_to_a_line_and_back():
    from rangekit.surface.cloud import PointCloud
    from rangekit.surface.mesh import TriangleMesh

    cloud = PointCloud(np.zeros((5, 3)))
    mesh = TriangleMesh(np.zeros((3, 3)), np.array([[0, 1, 2]]))
    T = np.arange(16.0).reshape(4, 4)
    events = [ev.StageStarted("decode"), ev.StageFinished("decode", 1.5), ev.Progress("a line", 1, 3),
              ev.ScanStarted(Path("/s"), 6, 2, 44, True, (2000, 8000), False), ev.ViewAcquired(1, 6, Path("/s/v"), 0.5, 44),
              ev.CaptureLoad(True, 3), ev.ViewDecoded(3, 6, "view_003", cloud), ev.FramesWritten(1, 6, 44),
              ev.MeshStarted("preview"),
              ev.ViewPlaced(3, 6, "view_003", cloud, T), ev.PairRegistered(0, 1, 1e-4, 0.8, False, "too little overlap"),
              ev.MeshReady("observed", Path("/s/mesh.ply"), mesh), ev.JobFailed(ValueError("bad\nthing")),
              JobExited(130, ("a", "b"))]
    for event in events:
        line = json.dumps(to_json(event))
        assert "\n" not in line
        back = from_json(json.loads(line))
        assert _same(event, back), (event, back)
    assert to_json(events[6]) == {"type": "ViewDecoded", "index": 3, "total": 6, "name": "view_003", "points": 5}
    assert to_json(events[9])["T_world_view"] == list(range(16))
    assert isinstance(from_json(to_json(events[12])).error, LoggedError)
    assert from_json(to_json(events[12])).error.kind == "ValueError"
    with pytest.raises(FileFormatError, match="type: expected one of"):
        from_json({"type": "Nothing"})
    with pytest.raises(FileFormatError, match="a ViewDecoded line"):
        from_json({"type": "ViewDecoded", "index": 1})


def test_events_wait_for_the_folder_then_a_reader_follows_from_an_offset(tmp_path):
    folder = tmp_path / "s"
    log = EventLog(folder)
    log(ev.Progress("before the folder"))
    assert not folder.exists()
    folder.mkdir()
    log(ev.StageStarted("acquire"))
    got = list(read_events(folder / EVENTS_FILE))
    assert [e for e, _ in got] == [ev.Progress("before the folder"), ev.StageStarted("acquire")]
    offset = got[-1][1]
    assert offset == (folder / EVENTS_FILE).stat().st_size
    assert list(read_events(folder / EVENTS_FILE, offset)) == []
    with open(folder / EVENTS_FILE, "a") as f:       # a line being written: left for the next call
        f.write('{"type": "StageFinished", "stage": "acquire", ')
    assert list(read_events(folder / EVENTS_FILE, offset)) == []
    with open(folder / EVENTS_FILE, "a") as f:
        f.write('"seconds": 2.0}\n')
    ((event, end),) = read_events(folder / EVENTS_FILE, offset)
    assert event == ev.StageFinished("acquire", 2.0) and end == (folder / EVENTS_FILE).stat().st_size
    assert list(read_events(tmp_path / "none" / EVENTS_FILE)) == []


def test_each_line_has_the_seconds_from_the_jobs_start_to_the_events_publishing(tmp_path):
    """A line's "t": when the event was published on the job's bus (not when the bus's thread got to it, behind a
    slow subscriber), counted from the log's making (the job's start), monotonic; lines without one (an older
    rangekit's, the web app's) read as before, their time None."""
    import threading
    import time

    from rangekit.app.bus import EventBus
    from rangekit.app.event_log import append_event, read_timeline

    folder = tmp_path / "s"
    folder.mkdir()
    log = EventLog(folder)
    gate = threading.Event()

    def slow(event):          # holds the bus's thread on the first event until the gate opens
        if isinstance(event, ev.Progress):
            gate.wait(30)

    with EventBus(slow, log) as bus:
        before = time.monotonic()
        bus.publish(ev.Progress("first"))
        bus.publish(ev.FramesWritten(0, 1, 44))
        published = time.monotonic()
        time.sleep(0.05)      # the second event waits behind the first on the bus's thread
        opened = time.monotonic()
        gate.set()
    append_event(folder, JobExited(0))    # the web app's line: no time
    with open(folder / EVENTS_FILE, "a") as f:   # an older rangekit's line
        f.write('{"type": "StageStarted", "stage": "decode"}\n')
    timeline = read_timeline(folder / EVENTS_FILE)
    assert [type(e).__name__ for _, e in timeline] == ["Progress", "FramesWritten", "JobExited", "StageStarted"]
    (t1, _), (t2, _) = timeline[:2]
    ms = 1e-4                 # a line's time is rounded to 0.1 ms
    assert before - log.start - ms <= t1 <= t2 <= published - log.start + ms
    assert t2 < opened - log.start - ms
    assert [t for t, _ in timeline[2:]] == [None, None]
    assert [type(e).__name__ for e, _ in read_events(folder / EVENTS_FILE)] == [type(e).__name__ for _, e in timeline]
    log(ev.MeshStarted("preview"))        # called off a bus (no publishing time): its own moment
    t3 = read_timeline(folder / EVENTS_FILE)[-1][0]
    assert opened - log.start - ms <= t3 <= time.monotonic() - log.start + ms


def _check_scan_log(folder: Path, seen: list | None, views: int) -> list:
    """The log's events: every view acquired then decoded, in the order of the subscriber's own (``seen``)."""
    logged = _typed(folder)
    if seen is not None:
        assert len(logged) == len(seen) and all(_same(a, b) for a, b in zip(seen, logged))
    kinds = [type(e).__name__ for e in logged]
    assert kinds[0] in ("Progress", "ScanStarted") and "ScanStarted" in kinds
    acquired = [e.index for e in logged if isinstance(e, ev.ViewAcquired)]
    decoded = [e.index for e in logged if isinstance(e, ev.ViewDecoded)]
    assert acquired == list(range(views)) and sorted(decoded) == list(range(views))
    for k in range(views):     # each view decoded after it was acquired
        at = {type(e).__name__: i for i, e in enumerate(logged) if getattr(e, "index", None) == k}
        assert at["ViewAcquired"] < at["ViewDecoded"]
    meshes = {e.kind: e.path.name for e in logged if isinstance(e, ev.MeshReady)}
    assert meshes["observed"] == "mesh.ply" and meshes["watertight"] == "mesh_watertight.ply"
    assert all(isinstance(e.cloud, LoggedCloud) and len(e.cloud) > 0 for e in logged if isinstance(e, ev.ViewDecoded))
    return logged


@pytest.mark.slow
def test_a_scan_in_process_and_as_a_child_write_every_views_events_in_order(tmp_path):
    options = dict(object="sphere", views=3, patterns="graycode", seed=1, report=False)
    seen: list = []
    rk.scan(ScanOptions(out=tmp_path / "call", **options), on_event=seen.append)
    logged = _check_scan_log(tmp_path / "call", seen, 3)
    assert isinstance(logged[-1], ev.StageFinished)
    child = subprocess.run([sys.executable, "-m", "rangekit", "-q", "scan", "--out", str(tmp_path / "child"),
                            "--object", "sphere", "--views", "3", "--patterns", "graycode", "--seed", "1",
                            "--no-report"], capture_output=True, text=True, stdin=subprocess.DEVNULL, timeout=900)
    assert child.returncode == 0, child.stderr
    by_child = _check_scan_log(tmp_path / "child", None, 3)
    # the same events; their interleaving across the streaming decoder's thread is the scheduler's
    # (each view's own order is checked above)
    kinds = lambda events: Counter(type(e).__name__ for e in events if not isinstance(e, (ev.Progress, ev.CaptureLoad)))
    assert kinds(by_child) == kinds(logged)
    stages = lambda events: [e.stage for e in events if isinstance(e, ev.StageStarted)]
    assert sorted(stages(by_child)) == sorted(stages(logged))


def test_a_resumed_scan_appends_to_the_log(tmp_path):
    from rangekit.formats.sessions.session import Session

    folder = tmp_path / "s"
    rk.scan(ScanOptions(out=folder, views=2, object="sphere", patterns="white", process=False))
    Session.load(folder).with_view_done(1, done=False).save()     # as a scan stopped after its first view
    first = (folder / EVENTS_FILE).read_bytes()
    rk.scan(ScanOptions(resume=folder, process=False))
    after = (folder / EVENTS_FILE).read_bytes()
    assert after.startswith(first) and len(after) > len(first)
    resumed = [e for e, _ in read_events(folder / EVENTS_FILE, len(first))]
    started = [e for e in resumed if isinstance(e, ev.ScanStarted)]
    assert len(started) == 1 and started[0].resume and (started[0].done, started[0].total) == (1, 2)
    assert [e.index for e in resumed if isinstance(e, ev.ViewAcquired)] == [1]
    assert [r.resume for r in _typed(folder) if isinstance(r, ev.ScanStarted)] == [False, True]
