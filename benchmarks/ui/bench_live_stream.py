"""The web app's live stream under load (issue 37): frames a second a page receives, and the server's CPU, with
and without a real-time scan running beside it; and a scan's acquisition with and without 20 page loads and 5
WebSocket clients hammering the server.

    .venv/bin/python benchmarks/ui/bench_live_stream.py [SECONDS [PAIRS]]   # default 20 s a phase, 1 pair

Everything on 127.0.0.1: ``rangekit ui --port 0`` started for real. Prints JSON.
"""

from __future__ import annotations

import json
import os
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))

from websockets.sync.client import connect  # noqa: E402

from support.ui_server import start_ui  # noqa: E402

from rangekit.ui.routes.page import STATIC  # noqa: E402


def _cpu_s(pid: int) -> float:
    with open(f"/proc/{pid}/stat") as f:
        parts = f.read().rsplit(")", 1)[1].split()
    return (int(parts[11]) + int(parts[12])) / os.sysconf("SC_CLK_TCK")


def _watch(server, seconds: float, stop: threading.Event | None = None) -> dict:
    frames, first = 0, None
    with connect(server.base.replace("http://", "ws://") + "/ws/live?ticket=" + server.ticket("/ws/live"),
                 origin=server.base) as ws:
        end = time.monotonic() + seconds
        while time.monotonic() < end and not (stop and stop.is_set()):
            msg = ws.recv(timeout=30)
            if isinstance(msg, bytes):
                frames += 1
                first = first or time.monotonic()
        span = time.monotonic() - first if first else float("nan")
    return {"frames": frames, "fps": round((frames - 1) / span, 2) if frames > 1 else 0.0}


def _scan_seconds(server, name: str, views: int = 3) -> float:
    server.request("/api/scan/start", data={"name": name, "views": views})
    t0 = time.monotonic()
    while True:
        s = json.loads(server.request("/api/scan")[1])
        if sum(v["done"] for v in s["views"]) == views and s["views"]:
            return time.monotonic() - t0
        if not s["running"] and s["exit_code"] not in (None, 0):
            raise RuntimeError(f"scan failed: {s['log'][-3:]}")
        time.sleep(0.2)


def _wait_ended(server) -> None:
    while json.loads(server.request("/api/scan")[1])["running"]:
        time.sleep(0.5)


def main(seconds: float, pairs: int = 1) -> dict:
    out: dict = {}
    with tempfile.TemporaryDirectory() as d:
        server = start_ui(d)
        try:
            _watch(server, 3)                                   # warm-up: the first frame's ray cast
            c0 = _cpu_s(server.proc.pid)
            out["alone"] = _watch(server, seconds)
            out["alone"]["server_cpu_per_s"] = round((_cpu_s(server.proc.pid) - c0) / seconds, 3)
            # With a real-time scan beside it (the scan's own process is not counted in the server's CPU).
            server.request("/api/scan/start", data={"name": "beside", "views": 3})
            time.sleep(3)
            c0 = _cpu_s(server.proc.pid)
            out["with_scan"] = _watch(server, seconds)
            out["with_scan"]["server_cpu_per_s"] = round((_cpu_s(server.proc.pid) - c0) / seconds, 3)
            _wait_ended(server)
            # A scan's acquisition alone, then with 20 page loads (the page and every file it loads) and 5 WebSocket
            # clients, ``pairs`` times in turn.
            from rangekit.formats.sessions.check import verify_views
            from rangekit.formats.sessions.session import Session

            page_files = ["/?token=" + server.token] + [f"/static/{p.name}" for p in sorted(STATIC.iterdir())
                                                        if p.suffix in (".js", ".css")]
            ratios, verified = [], 0
            for k in range(pairs):
                alone = _scan_seconds(server, f"quiet{k}")
                _wait_ended(server)
                stop = threading.Event()

                def loads() -> None:
                    while not stop.is_set():
                        for _ in range(20):
                            for path in page_files:
                                server.request(path, token=None if path.startswith("/?") else "header")
                        time.sleep(1.0)

                workers = [threading.Thread(target=loads)] + [
                    threading.Thread(target=_watch, args=(server, 10_000, stop)) for _ in range(5)]
                for w in workers:
                    w.start()
                loaded_s = _scan_seconds(server, f"loaded{k}")
                stop.set()
                for w in workers:
                    w.join()
                _wait_ended(server)
                ratios.append(loaded_s / alone)
                out.setdefault("acquisition_alone_s", []).append(round(alone, 2))
                out.setdefault("acquisition_loaded_s", []).append(round(loaded_s, 2))
                # Every frame of the loaded scan on disk and equal to its recorded SHA-256 (raises otherwise).
                loaded = Session.load(Path(d) / f"loaded{k}")
                verify_views(loaded)
                verified += sum(len(v.sha256 or {}) for v in loaded.views)
            out["acquisition_ratio_median"] = round(float(statistics.median(ratios)), 3)
            out["acquisition_ratios"] = [round(r, 3) for r in ratios]
            out["page_files_per_load"] = len(page_files)
            out["loaded_frames_verified"] = verified
        finally:
            server.stop()
    return out


if __name__ == "__main__":
    print(json.dumps(main(float(sys.argv[1]) if len(sys.argv) > 1 else 20.0,
                          int(sys.argv[2]) if len(sys.argv) > 2 else 1)))
