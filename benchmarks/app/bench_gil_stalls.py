"""How long the scan's streaming processing holds Python's GIL at a stretch: what stalls the capture beside it.

    PYTHONPATH=. .venv/bin/python benchmarks/app/bench_gil_stalls.py SESSION

SESSION: a coded-light session (``rangekit scan --out SESSION --no-process``). A copy without its caches and outputs
is fed through the scan's STREAMING worker (:class:`rangekit.app.runner.StreamingWorker` running
:class:`rangekit.app.scan.streaming.StreamingViews`) view by view, as a resumed scan would be
(every view but the last while the "acquisition" runs, so each view's work ahead is done), while a probe thread
sleeps 1 ms at a time and records how long each sleep really took. A gap much longer than 1 ms is time in which
no other Python thread could run: the capture's, in a real scan. Printed (JSON lines): the gaps over 15 ms (count,
summed seconds, the longest), and where the streaming thread was when the probe woke after each, summed by place.
Also: one Open3D cast of 2 M rays with the probe running, whole and through
:func:`rangekit.surface.raycast.query_scene`.
"""

from __future__ import annotations

import collections
import json
import shutil
import sys
import tempfile
import threading
import time
import traceback
from pathlib import Path

import numpy as np

STALL_S = 0.015


class Probe:
    """A thread sleeping 1 ms at a time; the gaps between its wake-ups, and where ``watch`` was after long ones."""

    def __init__(self, watch: str | None = None) -> None:
        self.watch, self.gaps, self.where = watch, [], collections.Counter()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()

    def _run(self) -> None:
        last = time.perf_counter()
        while not self._stop.is_set():
            time.sleep(0.001)
            now = time.perf_counter()
            gap, last = now - last, now
            self.gaps.append(gap)
            if gap > STALL_S and self.watch:
                for t in threading.enumerate():
                    if t.name == self.watch and t.ident in (frames := sys._current_frames()):
                        stack = traceback.extract_stack(frames[t.ident])[-3:]
                        self.where[" <- ".join(f"{Path(s.filename).name}:{s.name}" for s in reversed(stack))] += gap

    def summary(self) -> dict:
        g = np.array(self.gaps)
        long = g[g > STALL_S]
        return {"gaps_over_15ms": int(len(long)), "stalled_s": round(float(np.sum(long - 0.001)), 2),
                "longest_ms": round(float(g.max()) * 1e3, 1),
                "where": {k: round(v, 2) for k, v in self.where.most_common(6)}}


def cast_2m_rays() -> dict:
    import open3d as o3d

    from rangekit.surface.raycast import query_scene, raycasting_scene

    m = o3d.geometry.TriangleMesh.create_sphere(1.0, 400)
    scene = raycasting_scene(np.asarray(m.vertices), np.asarray(m.triangles))
    rays = np.zeros((2_000_000, 6), np.float32)
    rays[:, 3:] = np.random.default_rng(0).normal(size=(2_000_000, 3))
    scene.cast_rays(o3d.core.Tensor(rays[:10]))          # the BVH, built on the first cast
    out = {}
    for label, cast in (("whole", lambda: scene.cast_rays(o3d.core.Tensor(rays))),
                        ("query_scene", lambda: query_scene(scene, "cast_rays", rays))):
        with Probe() as probe:
            t0 = time.perf_counter()
            cast()
            out[label] = {"seconds": round(time.perf_counter() - t0, 3), **probe.summary()}
    return out


def streaming(session: Path) -> dict:
    from rangekit.app.events import ScanStarted
    from rangekit.app.process.options import ProcessOptions
    from rangekit.app.runner import StreamingWorker
    from rangekit.app.scan.streaming import StreamingViews
    from rangekit.formats.sessions.session import Session

    with tempfile.TemporaryDirectory() as tmp:
        copy = Path(tmp) / "session"
        shutil.copytree(session, copy, ignore=shutil.ignore_patterns(
            "cloud.ply", "maps.npz", "cloud.json", "*mesh*.ply", "merged.ply", "poses.json", "summary.json",
            "report.html", "preview.ply"))
        n = len(Session.load(copy).views)
        with Probe(watch="rangekit-streaming") as probe:
            t0 = time.perf_counter()
            proc = StreamingWorker(StreamingViews(copy, ProcessOptions()))
            proc.on_event(ScanStarted(copy, n, 0, 0, True, None, False))     # as a resumed scan: every view queued
            while len(proc.steps.decoded) < n - 1 and proc.error is None:        # the "acquisition" runs until then
                time.sleep(0.05)
            proc.finish()
            seconds = time.perf_counter() - t0
        if proc.error is not None:
            raise SystemExit(f"streaming failed: {proc.error!r}")
        return {"views": n, "seconds": round(seconds, 1), "measured_ahead": len(proc.steps.measured), **probe.summary()}


if __name__ == "__main__":
    print(json.dumps({"cast_2m_rays": cast_2m_rays()}))
    if len(sys.argv) > 1:
        print(json.dumps({"streaming": streaming(Path(sys.argv[1]))}))
