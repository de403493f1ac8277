"""The steps after a scan's last frame, one by one (issue 51: the preview within 1 s of the last frame): the last
view's read and checksum, decode, motion check, triangulation and cache writes, then the preview's placing,
integration, surface extraction and write, in wall and CPU seconds (this process: user + system).

    PYTHONPATH=. python benchmarks/app/scan/last_view_steps.py SESSION [--work /tmp/last_view] [--no-reuse]

The session is copied without its caches, views 0..n-2 go through the scan's streaming steps
(:class:`rangekit.app.scan.streaming.StreamingViews`) on this thread, then the last view's steps and the preview
are timed alone, nothing beside them (the scan runs its processing beside the preview: bench_after_last_frame.py
measures that). All inside one memory-reuse block, as the scan's streaming worker holds one from its first view to
the last (``--no-reuse``: none, as before issue 51's change), the last view's frames but its last read ahead as
while it is taken (untimed; ``--no-prefetch``: not). One JSON line: each span ``[s, CPU s]``.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import time
from contextlib import nullcontext
from pathlib import Path

CACHES = ("cloud.ply", "maps.npz", "cloud.json", "*.ply", "poses.json", "summary.json", "events.jsonl", "report.html")


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _read_ahead(steps, work: Path, n: int) -> None:
    """The last view's frames but its last read ahead (``StreamingViews.prefetch``) from its ``.partial`` folder, as
    while the capture takes it; then the view finished."""
    from rangekit.app.events import ViewAcquired
    from rangekit.formats.capture import list_images
    from rangekit.formats.sessions.files import partial_view_folder, view_folder

    final, partial = view_folder(work, n - 1), partial_view_folder(work, n - 1)
    final.rename(partial)
    last = list_images(partial)[-1]
    last.rename(work / last.name)
    steps.views_of(ViewAcquired(n - 2, n, view_folder(work, n - 2), 0.0, 0))
    steps.prefetch()
    (work / last.name).rename(last)
    partial.rename(final)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("session", type=Path)
    parser.add_argument("--work", type=Path, default=Path("/tmp/last_view_steps"))
    parser.add_argument("--no-reuse", action="store_true")
    parser.add_argument("--no-prefetch", action="store_true")
    args = parser.parse_args()

    import rangekit.app.process.view_cache as vc
    import rangekit.formats.meshes as meshes
    from rangekit._runtime.memory import reuse_freed_memory
    from rangekit.app.process.options import ProcessOptions
    from rangekit.app.scan.streaming import StreamingViews
    from rangekit.formats.sessions.session import Session
    from rangekit.surface.block_volume import BlockVolume

    if args.work.exists():
        shutil.rmtree(args.work)
    shutil.copytree(args.session, args.work, ignore=shutil.ignore_patterns(*CACHES))
    spans: dict = {}

    def timed(name, fn):
        def wrap(*a, **k):
            t, c = time.perf_counter(), _cpu()
            try:
                return fn(*a, **k)
            finally:
                s = spans.setdefault(name, [0.0, 0.0])
                s[0] += time.perf_counter() - t
                s[1] += _cpu() - c
        return wrap

    steps = StreamingViews(args.work, ProcessOptions(report=False))
    n = len(Session.load(args.work).views)
    with nullcontext() if args.no_reuse else reuse_freed_memory():
        for k in range(n - 1):
            steps.view(k)
        for name, attr in (("read+sha256", "read_view_stack"), ("decode", "decode_view"), ("motion", "_check_still"),
                           ("triangulate", "reconstruct_decoded"), ("write maps", "atomic_save_npz"),
                           ("write cloud", "atomic_write_with")):
            setattr(vc, attr, timed(name, getattr(vc, attr)))
        steps._place = timed("place", steps._place)
        steps._integrate = timed("integrate", steps._integrate)
        BlockVolume.mesh = timed("extract", BlockVolume.mesh)
        meshes.save_mesh = timed("save preview", meshes.save_mesh)
        if not args.no_prefetch:   # its frames but the last read ahead while it is taken (untimed)
            _read_ahead(steps, args.work, n)
        steps.acquisition_over = True
        t0, c0 = time.perf_counter(), _cpu()
        steps.view(n - 1)
        t1, c1 = time.perf_counter(), _cpu()
        steps.write_preview()
        t2, c2 = time.perf_counter(), _cpu()
    print(json.dumps({"load": round(os.getloadavg()[0], 2), "last view": [round(t1 - t0, 3), round(c1 - c0, 3)],
                      "preview": [round(t2 - t1, 3), round(c2 - c1, 3)], "total": [round(t2 - t0, 3), round(c2 - c0, 3)],
                      **{k: [round(v[0], 3), round(v[1], 3)] for k, v in spans.items()}}))
    shutil.rmtree(args.work, ignore_errors=True)


if __name__ == "__main__":
    main()
