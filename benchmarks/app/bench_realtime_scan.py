"""A real-time simulated scan (issue 36): ``rk.scan(ScanOptions(out=DIR, realtime=True, report=False))`` with each
event timed, printing (JSON) the acquisition time, how long after the last view was on disk the preview
(preview.ply) and the observed mesh (mesh.ply) were written, each view's decoding lag and the accuracy.

    .venv/bin/python benchmarks/app/bench_realtime_scan.py /tmp/rt_scan      # about 3 minutes, 12 views
    .venv/bin/python benchmarks/app/bench_realtime_scan.py /tmp/rt_scan --pairs 3

``--pairs N``: N pairs run in turn, a streaming scan then ``ScanOptions(process=False)`` (what ``rangekit scan
--realtime --no-process`` does), each into a fresh folder, printing both acquisition times and their ratio.
"""

from __future__ import annotations

import json
import sys
import time

import rangekit as rk
from rangekit.app import events as ev


def main(out: str) -> dict:
    times: dict = {}
    t0 = time.perf_counter()

    def on_event(event) -> None:
        now = time.perf_counter() - t0
        if isinstance(event, ev.ViewAcquired):
            times[f"acquired {event.index}"] = now
        elif isinstance(event, ev.ViewDecoded):
            times.setdefault(f"decoded {event.index}", now)
        elif isinstance(event, ev.MeshReady):
            times[event.kind] = now

    res = rk.scan(rk.ScanOptions(out=out, realtime=True, report=False), on_event=on_event)
    n = len(res.session.views)
    last = times[f"acquired {n - 1}"]
    return {"acquisition_s": res.acquisition_seconds, "preview_after_s": times.get("preview", float("nan")) - last,
            "mesh_after_s": times.get("observed", float("nan")) - last,
            "decode_lag_s": [round(times[f"decoded {k}"] - times[f"acquired {k}"], 2) for k in range(n)],
            "accuracy_rms_mm": None if res.processed.accuracy is None else res.processed.accuracy.rms * 1e3,
            "total_s": time.perf_counter() - t0}


def acquisition_only(out: str) -> float:
    """Seconds of a real-time scan's acquisition with no processing beside it."""
    return rk.scan(rk.ScanOptions(out=out, realtime=True, process=False)).acquisition_seconds


def pairs(out: str, n: int) -> None:
    import shutil
    import statistics

    rows = []
    for k in range(n):
        shutil.rmtree(out, ignore_errors=True)
        streamed = main(out)
        shutil.rmtree(out, ignore_errors=True)
        alone = acquisition_only(out)
        rows.append((streamed["acquisition_s"], alone))
        print(json.dumps({"pair": k + 1, "streaming": streamed, "no_process_acquisition_s": alone}), flush=True)
    ratios = [a / b for a, b in rows]
    print(json.dumps({"pairs": n, "acquisition_streaming_s": statistics.median(a for a, _ in rows),
                      "acquisition_no_process_s": statistics.median(b for _, b in rows),
                      "ratio_median": statistics.median(ratios), "ratio_range": [min(ratios), max(ratios)]}))


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[2] == "--pairs":
        pairs(sys.argv[1], int(sys.argv[3]))
    else:
        print(json.dumps(main(sys.argv[1])))
