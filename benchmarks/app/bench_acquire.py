"""Simulated acquisition against its speed target: ``rangekit scan --no-process`` of the default 12 views x 60 frames.

Target: at most 25 s wall on the 2-core machine. Runs the command ``--runs`` times into a temporary
folder (wall and CPU seconds of the child, user + sys, and its peak memory), checks that every frame's
SHA-256 equals the one recorded by ``--same-as`` (a session made before, e.g. by the serial acquisition of 605bab5),
then times the stages of one view in this process (CPU seconds: the machine may be shared):

    .venv/bin/python benchmarks/app/bench_acquire.py [--runs 1] [--same-as SESSION] [--markdown]

Prints a table and exits non-zero if the target is missed or a frame differs. ``--markdown`` prints
docs/benchmarks.md's row and stage sentence instead (a ``make docs-figures`` block: it says whether the
target was met and exits non-zero only if a frame differs).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

TARGET_S = 25.0


def _cpu(who=resource.RUSAGE_SELF) -> float:
    r = resource.getrusage(who)
    return r.ru_utime + r.ru_stime


def scan_once(out: Path) -> tuple[float, float, float]:
    """(wall s, CPU s, peak MB) of ``rangekit scan --out OUT --no-process`` in a child process."""
    before = _cpu(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    subprocess.run([sys.executable, "-m", "rangekit", "scan", "--out", str(out), "--no-process"], check=True,
                   stdout=subprocess.DEVNULL)
    wall = time.perf_counter() - t
    peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    return wall, _cpu(resource.RUSAGE_CHILDREN) - before, peak


def stages(session: Path) -> dict[str, float]:
    """CPU ms of each stage of one view (after a first view that warms the caches), in this process."""
    from rangekit.formats.sessions.session import Session
    from rangekit.io import atomic_write_bytes, encode_png
    from rangekit.formats.sessions.check import frame_sha256
    from rangekit.sim import SimRig, default_scene
    from rangekit.sim.imaging.sensor import Exposure, digitise

    s = Session.load(session)
    sim = SimRig(default_scene(s.simulator.object), s.rig, seed=s.simulator.seed)
    frames = list(s.pattern.frames())
    sim.turntable.rotate_to(0.0)
    sim.renderer().render(frames[0], sim.rng_for(frames[0]))      # warm up (compiled kernels loaded)
    sim.turntable.rotate_to(float(s.plan.angles()[1]))
    t = _cpu()
    r = sim.renderer()
    out = {"ray cast + renderer set-up (per view)": 1000 * (_cpu() - t)}
    acc = dict.fromkeys(("expected image (gather, blurs)", "sensor: noise + ADC", "PNG encode",
                         "atomic write + fsync", "SHA-256"), 0.0)
    keys = list(acc)
    with tempfile.TemporaryDirectory() as tmp:
        for p in frames:
            rng = sim.rng_for(p)
            t0 = _cpu()
            e = r.expected(p)
            t1 = _cpu()
            img = digitise(e, r.model, Exposure(), rng)
            t2 = _cpu()
            data = encode_png(img)
            t3 = _cpu()
            atomic_write_bytes(Path(tmp) / "f.png", data)
            t4 = _cpu()
            frame_sha256(data)
            t5 = _cpu()
            for k, a, b in zip(keys, (t0, t1, t2, t3, t4), (t1, t2, t3, t4, t5)):
                acc[k] += 1000 * (b - a) / len(frames)
    out.update(acc)
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--runs", type=int, default=1, help="scans to run (the minimum is reported)")
    ap.add_argument("--same-as", type=Path, default=None, help="a session whose frame SHA-256s must be equal")
    ap.add_argument("--markdown", action="store_true", help="print docs/benchmarks.md's block")
    args = ap.parse_args()
    say = (lambda *a, **k: print(*a, file=sys.stderr, **k)) if args.markdown else print
    say(f"machine: {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}")
    results = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.runs):
            out = Path(tmp) / f"scan{i}"
            results.append(scan_once(out))
            say(f"run {i + 1}: {results[-1][0]:.1f} s wall, {results[-1][1]:.1f} CPU-s, peak {results[-1][2]:.0f} MB")
        same = True
        if args.same_as is not None:
            a = json.loads((args.same_as / "session.json").read_text())["views"]
            b = json.loads((out / "session.json").read_text())["views"]
            same = [v.get("sha256") for v in a] == [v.get("sha256") for v in b]
            say(f"frames identical to {args.same_as}: {same}")
        table = stages(out)
    wall = float(np.min([r[0] for r in results]))
    if args.markdown:
        best = min(results)
        frames = "" if args.same_as is None else ("identical bytes" if same else "DIFFERENT")
        print("| | wall | CPU-s (user + sys) | peak | frames vs the shared session |\n|---|---|---|---|---|")
        print(f"| now (`make docs-figures`, min of {args.runs}) | {wall:.1f} s | {best[1]:.1f} | "
              f"{best[2] / 1024:.2f} GB | {frames} |")
        v = list(table.values())
        print(f"\nTarget <= {TARGET_S:.0f} s wall: {'met' if wall <= TARGET_S else 'not met'} in this run. One view's "
              f"stages, CPU ms: ray cast + renderer set-up {v[0]:.0f}; per frame: expected image {v[1]:.1f}, sensor "
              f"noise + ADC {v[2]:.1f}, PNG encode {v[3]:.1f}, atomic write + fsync {v[4]:.1f}, SHA-256 {v[5]:.1f}.")
        return 0 if same else 1
    print("\n| stage | CPU ms |\n|---|---|")
    for k, v in table.items():
        print(f"| {k} | {v:.1f} |")
    print(f"\nscan --no-process, 12 views x 60 frames: {wall:.1f} s wall (target <= {TARGET_S:.0f} s), "
          f"{min(r[1] for r in results):.1f} CPU-s")
    return 0 if wall <= TARGET_S and same else 1


if __name__ == "__main__":
    sys.exit(main())
