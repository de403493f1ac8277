"""What ``rangekit scan --realtime`` does after its last frame, replayed on a session's frames with no capture
(issue 51: the preview within 1 s of the last frame, mesh.ply within 3 s), side by side for two trees in one run.

    PYTHONPATH=. python benchmarks/app/scan/bench_after_last_frame.py /tmp/r49/S12 --old /work/main --pairs 2

Each run is a process of its own with the tree on PYTHONPATH: the session is copied without its caches and
outputs, views 0..n-2 go through the scan's streaming steps on its worker thread (as they would while the capture
runs; a tree that reads the last view's frames ahead as they are written, ``StreamingViews.prefetch``, has them
read but its last one, as while it is taken), then the clock starts where the last frame would be written: the last
view announced to the worker (its ``ViewAcquired``, as the scan's bus hands it on) and drained, then the preview and
the processing as :func:`rangekit.app.scan.scan.scan` does after its acquisition (``_preview_then_process`` where the
tree has it: the preview first; else the preview beside the processing), with the scan's default fusion
(``SCAN_FUSION``: blocks since issue 51 M6; Poisson before). Printed per run (one JSON line): the seconds from
there to the last view decoded, the preview, the registration's end (poses.json), mesh.ply and the closed mesh, and
the CPU seconds this process used by each (user + system; the Poisson child's are not in it: it is the same
code on both sides). The machine's load makes the seconds noisy; the CPU seconds say what work is left after the
last frame. The capture itself is bench_time_to_mesh.py's.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parents[3]
CACHES = ("cloud.ply", "maps.npz", "cloud.json", "*.ply", "poses.json", "summary.json", "events.jsonl", "report.html")


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def replay(session: Path, work: Path) -> dict:
    """One replay (module doc) of ``session`` in ``work`` (removed first): each span's seconds and CPU seconds."""
    from rangekit._runtime.executor import Where, start
    from rangekit.app.bus import EventBus
    from rangekit.app.events import MeshReady, StageFinished, ViewDecoded
    from rangekit.app.process.options import ProcessOptions
    from rangekit.app.runner import Plan, StreamingWorker
    import rangekit.app.scan.scan as scan_module
    from rangekit.app.events import ViewAcquired
    from rangekit.formats.sessions.files import view_folder
    from rangekit.app.scan.streaming import StreamingViews
    from rangekit.formats.sessions.session import Session

    if work.exists():
        shutil.rmtree(work)
    shutil.copytree(session, work, ignore=shutil.ignore_patterns(*CACHES))
    clock: dict = {}
    t0 = c0 = None

    def mark(name: str) -> None:
        if t0 is not None and name not in clock:
            clock[name] = (round(time.perf_counter() - t0, 2), round(_cpu() - c0, 2))

    def on_event(event) -> None:
        if isinstance(event, ViewDecoded) and event.index == event.total - 1:
            mark("decoded")
        elif isinstance(event, MeshReady):
            mark(event.kind)
        elif isinstance(event, StageFinished) and event.stage == "register":
            mark("registered")

    try:   # the scan's own fusion (a tree before issue 51 M6: Poisson, ProcessOptions' default)
        from rangekit.app.scan.options import SCAN_FUSION
        options = ProcessOptions(report=False, fusion=SCAN_FUSION)
    except ImportError:
        options = ProcessOptions(report=False)
    with EventBus(on_event) as bus:
        worker = StreamingWorker(StreamingViews(work, options, bus))
        n = len(Session.load(work).views)
        for k in range(n - 1):        # on the streaming worker's thread, as during a scan (its memory reuse too)
            worker._worker.put(k)
        while len(worker.steps.decoded) + len(worker.steps.moved) < n - 1 and worker.error is None:
            time.sleep(0.02)
        if getattr(worker.steps, "prefetch", None) is not None:
            _taking_the_last_view(worker, work, n)
        bus.flush()
        t0, c0 = time.perf_counter(), _cpu()
        # view n-1 acquired: its last frame is on disk
        worker.on_event(ViewAcquired(n - 1, n, view_folder(work, n - 1), 0.0, 0))
        worker.drain()
        after = getattr(scan_module, "_preview_then_process", None)
        if after is not None:
            after(worker, Session.load(work), options, bus)
        else:                                         # an older tree: the preview beside the processing
            with start(Where.THREAD, worker.write_preview) as preview:
                memo = worker.memo()
                memo.before_mesh = scan_module._waiting(preview)
                scan_module._process(Session.load(work), options, bus, Plan.STREAMING, memo)
                preview.result()
        bus.flush()
    accuracy = json.loads((work / "summary.json").read_text())["accuracy"]
    return {"spans_s_cpu": clock, "rms_mm": round(accuracy["rms"] * 1e3, 4), "completeness": accuracy["completeness"]}


def _taking_the_last_view(worker, work: Path, n: int) -> None:
    """The last view as while it is taken (a tree whose steps read its frames ahead, ``StreamingViews.prefetch``):
    its frames but the last in its ``.partial`` folder, read by the worker while it waits; then its last frame
    written and the view finished, as the capture does."""
    from rangekit.app.events import ViewAcquired
    from rangekit.formats.capture import list_images
    from rangekit.formats.sessions.files import partial_view_folder, view_folder

    final, partial = view_folder(work, n - 1), partial_view_folder(work, n - 1)
    final.rename(partial)
    frames = list_images(partial)
    held = work / "last_frame"
    held.mkdir()
    frames[-1].rename(held / frames[-1].name)
    worker.steps.views_of(ViewAcquired(n - 2, n, view_folder(work, n - 2), 0.0, len(frames)))
    worker._worker.put(n - 2)        # done already: the worker then waits, reading the last view's frames ahead
    t0 = time.perf_counter()
    while time.perf_counter() - t0 < 60:
        got = worker.steps._frames
        if got is not None and len(got.sha256) == len(frames) - 1:
            break
        time.sleep(0.02)
    (held / frames[-1].name).rename(partial / frames[-1].name)
    partial.rename(final)
    held.rmdir()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("session", type=Path)
    parser.add_argument("--old", type=Path, required=True)
    parser.add_argument("--new", type=Path, default=HERE)
    parser.add_argument("--pairs", type=int, default=2)
    parser.add_argument("--out", type=Path, default=Path("/tmp/after_last_frame"))
    parser.add_argument("--one", type=Path, help=argparse.SUPPRESS)   # a child run: the work folder
    args = parser.parse_args()
    if args.one is not None:
        print(json.dumps(replay(args.session, args.one)))
        return
    rows: dict = {"old": [], "new": []}
    for pair in range(args.pairs):
        for row in ("old", "new") if pair % 2 == 0 else ("new", "old"):
            tree = args.old if row == "old" else args.new
            load = round(os.getloadavg()[0], 2)
            out = subprocess.run([sys.executable, str(Path(__file__).resolve()), str(args.session), "--old", ".",
                                  "--one", str(args.out / f"{row}_{pair}")], cwd=tree, capture_output=True, text=True,
                                 env={**os.environ, "PYTHONPATH": str(tree)}, check=True)
            got = {"pair": pair, "row": row, "load": load, **json.loads(out.stdout.strip().splitlines()[-1])}
            rows[row].append(got)
            print(json.dumps(got), flush=True)
    for row, runs in rows.items():
        spans = sorted({s for r in runs for s in r["spans_s_cpu"]}, key=lambda s: runs[0]["spans_s_cpu"].get(s, (0,))[0])
        print(json.dumps({"row": row, "median [s, CPU s]": {
            s: [statistics.median(r["spans_s_cpu"][s][i] for r in runs if s in r["spans_s_cpu"]) for i in (0, 1)]
            for s in spans}}))
    shutil.rmtree(args.out, ignore_errors=True)


if __name__ == "__main__":
    main()
