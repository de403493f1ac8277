"""Dask's nanny sets ``MALLOC_TRIM_THRESHOLD_=65536``: what it costs ``rangekit process`` (docs/scale.md).

    PYTHONPATH=. python benchmarks/app/bench_malloc_trim.py PROCESSED_SESSION [--markdown]

PROCESSED_SESSION (left unchanged) is a session ``rangekit process`` has processed (its views cached, so
decoding is not redone). Two copies of it are made in the docs' scratch folder (``$RANGEKIT_DOCS_WORK``,
else build/docs-figures); ``rangekit process COPY --no-report`` runs on the first with the variable set and
on the second without it, each under ``benchmarks/harness/tree_peak.py`` (CPU of the process tree, user and sys
apart). Prints the system and total CPU seconds of both runs; ``--markdown`` the sentence of docs/scale.md
(a ``make docs-figures`` block). A timing on a shared machine: the lead's idle run is the one to quote.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]  # the repo (this is benchmarks/app/bench_malloc_trim.py)
TREE_PEAK = REPO / "benchmarks" / "harness" / "tree_peak.py"
WORK = Path(os.environ.get("RANGEKIT_DOCS_WORK") or REPO / "build" / "docs-figures")
THRESHOLD = "65536"


def run(session: Path, copy: Path, trim: bool) -> tuple[float, float]:
    """(sys CPU-s, user + sys CPU-s) of ``rangekit process COPY --no-report`` with or without the variable."""
    shutil.rmtree(copy, ignore_errors=True)
    shutil.copytree(session, copy)
    env = dict(os.environ)
    env.pop("MALLOC_TRIM_THRESHOLD_", None)
    if trim:
        env["MALLOC_TRIM_THRESHOLD_"] = THRESHOLD
    try:
        done = subprocess.run([sys.executable, str(TREE_PEAK), "--", sys.executable, "-m",
                               "rangekit", "-q", "process", str(copy), "--no-report"], cwd=REPO, env=env,
                              stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
    finally:
        shutil.rmtree(copy, ignore_errors=True)
    if done.returncode:
        raise SystemExit(f"rangekit process {copy} --no-report failed (exit {done.returncode}):\n{done.stderr[-3000:]}")
    m = re.search(r"run: [\d.]+ s wall, ([\d.]+) CPU-s \(([\d.]+) user \+ ([\d.]+) sys\)", done.stderr)
    if not m:
        raise SystemExit("could not read tree_peak's line from the output:\n" + done.stderr[-2000:])
    return float(m[3]), float(m[1])


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("session", type=Path, help="a processed session (views cached)")
    ap.add_argument("--markdown", action="store_true", help="print docs/scale.md's sentence")
    args = ap.parse_args()
    if not (args.session / "summary.json").exists():
        raise SystemExit(f"{args.session}: expected a processed session (summary.json), found none")
    with_sys, with_all = run(args.session, WORK / "trim_with", True)
    without_sys, without_all = run(args.session, WORK / "trim_without", False)
    if args.markdown:
        print(f"The nanny's `MALLOC_TRIM_THRESHOLD_={THRESHOLD}` (replaced by `--scheduler local`'s malloc settings, see above) "
              f"multiplies the system time of\none `rangekit process --no-report` of a processed session (its "
              f"views cached) by {with_sys / without_sys:.1f}: {with_sys:.1f} against {without_sys:.1f} s "
              f"({with_all:.1f} against {without_all:.1f} CPU-s in all;\n`PYTHONPATH=. python "
              "benchmarks/app/bench_malloc_trim.py PROCESSED_SESSION`, one run each on copies of the session).")
        return 0
    print(f"with MALLOC_TRIM_THRESHOLD_={THRESHOLD}: {with_sys:.1f} sys CPU-s, {with_all:.1f} CPU-s in all")
    print(f"without it:                       {without_sys:.1f} sys CPU-s, {without_all:.1f} CPU-s in all")
    return 0


if __name__ == "__main__":
    sys.exit(main())
