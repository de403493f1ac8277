"""A scan placed step by step after its last frame, from its session's ``events.jsonl`` (issue 51: each line's
``"t"``, the seconds from the job's start to the event, :func:`rangekit.app.event_log.read_timeline`):

    PYTHONPATH=. python benchmarks/app/scan/after_last_frame.py SESSION [SESSION ...]

Printed per session: each event from the last view's ``FramesWritten`` (its last frame on disk) on, its seconds
after it, up to the closed mesh; progress lines, the capture's load and the pairs left out. Then the spans a person
waits for: to the last view acquired (view.json, its folder renamed, session.json), to its cache written
(``ViewDecoded``), to the preview written (``MeshReady`` preview), to mesh.ply and mesh_watertight.ply. Any scan of
a rangekit that writes the times, a realtime one or not; a resumed scan's lines count from its own start (the last
job of the file is read).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from rangekit.app import events as ev
from rangekit.app.event_log import read_timeline
from rangekit.formats.sessions.files import EVENTS_FILE

QUIET = (ev.Progress, ev.CaptureLoad, ev.PairRegistered)


def after_last_frame(folder: Path) -> tuple[list[str], dict]:
    """The lines (module doc) of ``folder``'s last scan, and its spans (seconds after the last frame)."""
    timeline = read_timeline(folder / EVENTS_FILE)
    starts = [i for i, (_, e) in enumerate(timeline) if isinstance(e, ev.ScanStarted)]
    timeline = timeline[starts[-1]:] if starts else timeline
    written = [(t, e) for t, e in timeline if isinstance(e, ev.FramesWritten) and e.index == e.total - 1]
    if not written or written[-1][0] is None:
        raise SystemExit(f"{folder}: no time of the last view's last frame in {EVENTS_FILE} (an older rangekit?)")
    t0 = written[-1][0]
    lines, spans = [], {}
    for t, e in timeline:
        if t is None or t < t0 or isinstance(e, QUIET):
            continue
        what = {k: v for k, v in vars(e).items() if k in ("index", "stage", "kind")}
        lines.append(f"{t - t0:+8.3f} s  {type(e).__name__} {json.dumps(what, default=str)}")
        name = {ev.ViewAcquired: "acquired", ev.ViewDecoded: "cache"}.get(type(e))
        if name and e.index == e.total - 1:
            spans.setdefault(name, round(t - t0, 3))
        if isinstance(e, ev.MeshReady):
            spans.setdefault(e.kind, round(t - t0, 3))
    return lines, spans


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("sessions", type=Path, nargs="+")
    args = parser.parse_args()
    for folder in args.sessions:
        lines, spans = after_last_frame(folder)
        print(f"{folder}:\n  " + "\n  ".join(lines))
        print(json.dumps({"session": str(folder), "after the last frame [s]": spans}))


if __name__ == "__main__":
    main()
