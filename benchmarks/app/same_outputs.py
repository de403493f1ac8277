"""The outputs of the main job, byte for byte, from two source trees (issue 49's acceptance: a change that moves
the concurrency must not change a byte of what the job writes).

``run`` runs, with ``PYTHONPATH=TREE python -m rangekit ...`` (TREE a checkout of the repo, its ``rangekit/``
holding the sim, drivers and calib links), the five scenarios of the acceptance and copies each one's
mesh.ply, mesh_watertight.ply, poses.json and summary.json into OUT/SCENARIO/:

- ``scan``: ``rangekit scan --out S --views N`` (the defaults but the views: N is ``--views``, 6 unless told;
  the default scan's 12 takes twice as long);
- ``process``: ``rangekit process`` of a copy of that session, its outputs and view caches removed;
- ``dask_a``, ``dask_b``: ``rangekit process A B`` of two such copies (several sessions: the Dask batch on a
  local cluster of its default 2 workers on 127.0.0.1);
- ``realtime``: ``rangekit scan --out R --views N --realtime``;
- ``resume``: ``rangekit scan --out S2 --views N`` stopped by SIGINT once ``view N/2 of N done`` is printed
  (``view 3/6 done`` at 6), then ``rangekit scan --resume S2``.

Each scenario's log and wall/CPU seconds go to OUT/logs/, and the views to OUT/logs/run.json. ``compare`` says,
file by file, identical or not; summary.json is compared with every timing entry removed (a key named ``seconds``
or ending in ``_seconds`` or ``_s``) and a top-level ``options`` entry ignored (issue 49 records the options
there).

    python benchmarks/app/same_outputs.py run --tree /work/wt-base --out /work/baseline-49
    python benchmarks/app/same_outputs.py run --tree . --out /tmp/mine [--only scan,process]
    python benchmarks/app/same_outputs.py run --tree /work/wt-base --views 12 --only scan,realtime \\
        --out /work/baseline-49-v12
    python benchmarks/app/same_outputs.py compare /work/baseline-49 /tmp/mine

``compare`` looks only at the scenarios the base holds, and refuses two runs made at different views.

Under load on the 2-core machine a run takes about 8 minutes.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

FILES = ("mesh.ply", "mesh_watertight.ply", "poses.json", "summary.json")
SCENARIOS = ("scan", "process", "dask_a", "dask_b", "realtime", "resume")
#: What processing writes into a session (its outputs and each view's cache): removed from a copy to process.
OUTPUTS = ("mesh.ply", "mesh_watertight.ply", "poses.json", "summary.json", "merged.ply", "report.html",
           "preview.ply")
VIEW_CACHE = ("cloud.ply", "maps.npz", "cloud.json")


def _cpu() -> float:
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


class Runner:
    """Runs ``python -m rangekit`` in one tree, logging each run into ``logs``."""

    def __init__(self, tree: Path, python: str, logs: Path) -> None:
        self.tree, self.python, self.logs = tree, python, logs
        self.env = {**os.environ, "PYTHONPATH": str(tree), "PYTHONUNBUFFERED": "1"}
        self.times: dict[str, dict] = {}

    def run(self, name: str, *args: str) -> None:
        t0, c0 = time.perf_counter(), _cpu()
        with open(self.logs / f"{name}.log", "w") as log:
            rc = subprocess.run([self.python, "-m", "rangekit", *args], cwd=self.tree, env=self.env, stdout=log,
                                stderr=subprocess.STDOUT).returncode
        self._record(name, t0, c0)
        if rc != 0:
            raise SystemExit(f"{name}: rangekit {' '.join(args)} exited {rc}; see {self.logs / name}.log")

    def run_until(self, name: str, pattern: str, *args: str) -> int:
        """``rangekit ARGS`` sent SIGINT once a line holds ``pattern``; its exit code."""
        t0, c0 = time.perf_counter(), _cpu()
        with open(self.logs / f"{name}.log", "w") as log:
            proc = subprocess.Popen([self.python, "-m", "rangekit", *args], cwd=self.tree, env=self.env,
                                    stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                    preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
            for line in proc.stdout:
                log.write(line)
                if pattern in line:
                    proc.send_signal(signal.SIGINT)
                    break
            log.write(proc.communicate(timeout=600)[0])
        self._record(name, t0, c0)
        return proc.returncode

    def _record(self, name: str, t0: float, c0: float) -> None:
        self.times[name] = {"wall_s": round(time.perf_counter() - t0, 1), "cpu_s": round(_cpu() - c0, 1)}


def _keep(session: Path, into: Path) -> None:
    into.mkdir(parents=True, exist_ok=True)
    for name in FILES:
        shutil.copy2(session / name, into / name)


def _unprocessed_copy(session: Path, to: Path) -> Path:
    shutil.copytree(session, to)
    for name in OUTPUTS:
        (to / name).unlink(missing_ok=True)
    for view in to.glob("view_*"):
        for name in VIEW_CACHE:
            (view / name).unlink(missing_ok=True)
    return to


def run(tree: Path, out: Path, python: str, only: set[str], views: int = 6) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / "logs").mkdir(exist_ok=True)
    r = Runner(tree.resolve(), python, out / "logs")
    scan_views = ["--views", str(views)]
    with tempfile.TemporaryDirectory(prefix="same_outputs_") as tmp:
        work = Path(tmp)
        scanned = work / "scan"
        if only & {"scan", "process", "dask_a", "dask_b"}:
            r.run("scan", "scan", "--out", str(scanned), *scan_views)
            _keep(scanned, out / "scan")
        if "process" in only:
            copy = _unprocessed_copy(scanned, work / "process")
            r.run("process", "process", str(copy))
            _keep(copy, out / "process")
        if only & {"dask_a", "dask_b"}:
            a, b = _unprocessed_copy(scanned, work / "dask_a"), _unprocessed_copy(scanned, work / "dask_b")
            r.run("dask", "process", str(a), str(b))
            _keep(a, out / "dask_a")
            _keep(b, out / "dask_b")
        if "realtime" in only:
            r.run("realtime", "scan", "--out", str(work / "realtime"), *scan_views, "--realtime")
            _keep(work / "realtime", out / "realtime")
        if "resume" in only:
            s = work / "resume"
            rc = r.run_until("resume_stopped", f"view {views // 2}/{views} done", "scan", "--out", str(s), *scan_views)
            if rc != 130:
                raise SystemExit(f"resume: the interrupted scan exited {rc}, expected 130; see logs/resume_stopped.log")
            r.run("resume", "scan", "--resume", str(s))
            _keep(s, out / "resume")
    head = subprocess.run(["git", "-C", str(tree), "rev-parse", "HEAD"], capture_output=True, text=True).stdout.strip()
    dirty = subprocess.run(["git", "-C", str(tree), "status", "--porcelain", "--untracked-files=no"],
                           capture_output=True, text=True).stdout.strip()
    (out / "logs" / "run.json").write_text(json.dumps({"tree": str(tree), "commit": head, "dirty": bool(dirty),
                                                       "views": views, "times": r.times}, indent=1))
    print(json.dumps(r.times, indent=1))


def _timeless(value):
    """summary.json without its timings (keys ``seconds``, ``*_seconds``, ``*_s``)."""
    if isinstance(value, dict):
        return {k: _timeless(v) for k, v in value.items()
                if not (k == "seconds" or k.endswith("_seconds") or k.endswith("_s"))}
    if isinstance(value, list):
        return [_timeless(v) for v in value]
    return value


def same(a: Path, b: Path) -> bool:
    if a.name == "summary.json":
        da, db = json.loads(a.read_text()), json.loads(b.read_text())
        da.pop("options", None)
        db.pop("options", None)
        return _timeless(da) == _timeless(db)
    return a.read_bytes() == b.read_bytes()


def _views(out: Path) -> int:
    """The views a run was made at (6 for a run from before ``--views``)."""
    run_json = out / "logs" / "run.json"
    return json.loads(run_json.read_text()).get("views", 6) if run_json.is_file() else 6


def compare(base: Path, other: Path) -> int:
    if _views(base) != _views(other):
        print(f"{base} was run at {_views(base)} views, {other} at {_views(other)}: not comparable")
        return 1
    differ = 0
    for scenario in (s for s in SCENARIOS if (base / s).is_dir()):
        for name in FILES:
            a, b = base / scenario / name, other / scenario / name
            if not (a.is_file() and b.is_file()):
                print(f"{scenario}/{name}: missing in {base if not a.is_file() else other}")
                continue
            ok = same(a, b)
            differ += not ok
            print(f"{scenario}/{name}: {'identical' if ok else 'DIFFERS'}")
    print("all identical" if not differ else f"{differ} file(s) differ")
    return 1 if differ else 0


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="run the scenarios in a tree")
    r.add_argument("--tree", required=True, type=Path, help="the checkout to run (PYTHONPATH)")
    r.add_argument("--out", required=True, type=Path, help="where each scenario's files go")
    r.add_argument("--python", default=sys.executable, help="the interpreter (default: this one)")
    r.add_argument("--views", type=int, default=6, help="the views of every scan (default 6; at least 2)")
    r.add_argument("--only", default=",".join(s for s in SCENARIOS if s != "dask_b"),
                   help="comma-separated scenarios (default all; dask_a and dask_b run together)")
    c = sub.add_parser("compare", help="file by file, identical or not")
    c.add_argument("base", type=Path)
    c.add_argument("other", type=Path)
    args = p.parse_args()
    if args.command == "run":
        only = set(args.only.split(","))
        unknown = only - set(SCENARIOS)
        if unknown:
            p.error(f"--only: unknown scenario(s) {', '.join(sorted(unknown))}; expected of {', '.join(SCENARIOS)}")
        if args.views < 2:
            p.error(f"--views: got {args.views}, expected at least 2")
        run(args.tree, args.out, args.python, only, args.views)
        return 0
    return compare(args.base, args.other)


if __name__ == "__main__":
    sys.exit(main())
