"""The README's figures of the default scan (`make scan`), for tools/docs_figures.py.

    python tools/docs_scan.py summary      # the README's paragraph on make scan, with this run's figures
    python tools/docs_scan.py report-png   # docs/img/report.png from the same scan's report.html
    python tools/docs_scan.py session      # prints the path of a default 12-view session, unprocessed

The first two share one default scan, ``$RANGEKIT_DOCS_WORK/scan1`` (build/docs-figures/scan1 when the
variable is unset), made on first use by ``rangekit scan --out scan1`` (run in that folder, so that the
report reads as ``make scan``'s) under benchmarks/harness/tree_peak.py (wall time, peak memory of the process tree).
Run it on an otherwise idle machine: the times are wall times.

The session (``$RANGEKIT_DOCS_WORK/session12``, ``rangekit scan --out ... --no-process``, made on first use)
is the input of the benchmarks that time ``rangekit process`` and its stages: they must work on a copy.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
WORK = Path(os.environ.get("RANGEKIT_DOCS_WORK", REPO / "build" / "docs-figures"))
SCAN = WORK / "scan1"
RUN = WORK / "scan1_run.json"


def ensure_scan() -> dict:
    """{wall_s, peak_gb, acquisition_s} of the shared scan, running it first when it is not there."""
    if RUN.exists() and (SCAN / "summary.json").exists():
        return json.loads(RUN.read_text())
    shutil.rmtree(SCAN, ignore_errors=True)         # a half-made one from an interrupted run
    WORK.mkdir(parents=True, exist_ok=True)
    done = subprocess.run([sys.executable, str(REPO / "benchmarks" / "harness" / "tree_peak.py"), "--",
                           sys.executable, "-m", "rangekit", "scan", "--out", SCAN.name],
                          cwd=WORK, env=dict(os.environ, PYTHONPATH=str(REPO)), stdout=subprocess.PIPE,
                          stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
    output = done.stdout + done.stderr
    if done.returncode:
        raise SystemExit(f"rangekit scan --out {SCAN} failed (exit {done.returncode}):\n{output[-3000:]}")
    timing = re.search(r"run: ([\d.]+) s wall, .* peak of the process tree ([\d.]+) GB", output)
    acquisition = re.search(r"acquisition: (?:(\d+) min )?([\d.]+) s", output)
    if not timing or not acquisition:
        raise SystemExit("could not read the wall time, peak or acquisition time from the scan's output:\n"
                         + output[-2000:])
    run = {"wall_s": float(timing[1]), "peak_gb": float(timing[2]),
           "acquisition_s": 60 * int(acquisition[1] or 0) + float(acquisition[2])}
    RUN.write_text(json.dumps(run))
    return run


def ensure_session() -> Path:
    """The shared default 12-view session (acquired, not processed), made on first use."""
    session = WORK / "session12"
    if not (session / "session.json").exists():
        shutil.rmtree(session, ignore_errors=True)      # a half-made one from an interrupted run
        WORK.mkdir(parents=True, exist_ok=True)
        done = subprocess.run([sys.executable, "-m", "rangekit", "-q", "scan", "--out", str(session), "--no-process"],
                              cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                              stdin=subprocess.DEVNULL)
        if done.returncode:
            raise SystemExit(f"rangekit scan --out {session} --no-process failed (exit {done.returncode}):\n"
                             f"{done.stderr[-3000:]}")
    return session


def summary() -> str:
    """The README's make-scan paragraphs with this run's figures."""
    run = ensure_scan()
    s = json.loads((SCAN / "summary.json").read_text())
    sec, acc = s["seconds"], s["accuracy"]
    closed = acc["watertight"]
    stages = ", ".join(f"{k} {v:.1f}" + (" (beside the fusion)" if k == "evaluate" else "") for k, v in sec.items())
    processing = run["wall_s"] - run["acquisition_s"]
    n_views = len(s["views"])
    n_frames = len(json.loads((SCAN / "session.json").read_text())["pattern"]["frames"])   # the default patterns'
    return "\n".join([
        f"`make scan` runs `rangekit scan --out scan1` on the simulated rig. It took {run['wall_s']:.0f} s on 2 cores,",
        f"with a peak of {run['peak_gb']:.1f} GB over its processes (`make docs-figures`, an idle machine):",
        "",
        f"- **Acquisition, {run['acquisition_s']:.0f} s**: {n_views} turntable views of the `lumpy` object, {n_frames} hybrid "
        "frames each (Gray",
        "  code + phase shift), rendered, encoded and written on both cores.",
        f"- **Processing, {processing:.0f} s** (stages, s: {stages}): every view decoded and",
        "  triangulated, then registered from the turntable angles and refined, then fused into `scan1/mesh.ply`,",
        "  the surface the views observed (nothing invented), and `scan1/mesh_watertight.ply`, the same surface",
        "  closed, each vertex flagged `observed` or not; both measured against the true surface and drawn into",
        "  the report.",
        "",
        "It also writes `summary.json` and `report.html`. Where the views can see the object, `mesh.ply` is",
        f"{acc['rms'] * 1e3:.3f} mm RMS ({acc['rms'] / acc['diagonal'] * 100:.3f}% of the object's diagonal, 95th "
        f"percentile {acc['p95'] * 1e3:.3f} mm, completeness",
        f"{acc['completeness'] * 100:.1f}%) from the true surface; the closed mesh {closed['rms'] * 1e3:.2f} mm RMS, "
        "set by the part it fills in.",
    ])


def report_png() -> str:
    """Screenshot the shared scan's report into docs/img/report.png; the markdown that shows it."""
    ensure_scan()
    out = REPO / "docs" / "img" / "report.png"
    done = subprocess.run([sys.executable, str(REPO / "tests" / "support" / "chromium.py"), str(SCAN / "report.html"),
                           "--screenshot", str(out), "--viewport-only"], cwd=REPO, stdout=subprocess.DEVNULL,
                          stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
    if done.returncode:
        raise SystemExit(f"screenshot of {SCAN / 'report.html'} failed (exit {done.returncode}; needs chromium "
                         f"and chromedriver: make browser):\n{done.stderr[-2000:]}")
    return "![report](docs/img/report.png)"


if __name__ == "__main__":
    what = sys.argv[1:2]
    if what == ["summary"]:
        print(summary())
    elif what == ["session"]:
        print(ensure_session())
    elif what == ["report-png"]:
        print(report_png())
    else:
        raise SystemExit("usage: python tools/docs_scan.py summary|report-png|session")
