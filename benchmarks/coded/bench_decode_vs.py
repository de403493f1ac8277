"""Coded-light decoding and ``rangekit reconstruct`` of this tree against another checkout, side by side (issue 47).

    PYTHONPATH=. .venv/bin/python benchmarks/coded/bench_decode_vs.py OLD_TREE [--pairs 5] [--repeat 5]
        [--sizes 1280x1024,2048x1536] [--folder-root /tmp/rangekit-bench/decode_vs] [--no-cli] [--markdown]

OLD_TREE is another checkout of rangekit (e.g. ``git worktree add ../old 302926b``; it needs the same
``rangekit/sim`` etc. as this one). The captures are Gray-code folders (column and row bits, white, black)
rendered once by this tree's ``rangekit sim render --patterns graycode --object lumpy --seed 0`` into
``--folder-root``/``graycode_WxH`` and reused: 1280x1024 is the default rig (1280x800 projector, 44 images);
another size is the default rig with its camera resized to it (same field of view) and its projector to
1920x1080 (46 images).

Two measurements, each run by the two trees in turn (this, old, old, this, ...: the order swaps every pair so
a drift of the machine's speed falls on both), ``--pairs`` pairs, every figure the minimum over the pairs and
the ratio this / old both of the minima and pair by pair (median, range):

1. In process (a child ``python`` with ``PYTHONPATH`` set to the tree): the folder loaded once, then
   ``--repeat`` calls, after one untimed (numba's cache), of :func:`rangekit.coded.decode.decode` as
   ``rangekit reconstruct`` calls it (subpixel, the capture's full scale and the rig's projector response),
   ``decode(..., motion=True)`` as ``rangekit decode`` calls it, and the whole
   :func:`rangekit.coded.reconstruct.reconstruct_view`; the child's minimum wall seconds of each.
   Where the tree has the rig check (:func:`rangekit.rig.capture_check.check_rig`, called inside
   ``reconstruct_view`` since issue 47) it is also timed alone on the same view's coordinates, and its share of
   ``reconstruct_view`` printed.
2. Whole process (``--no-cli`` skips it): ``python -m rangekit reconstruct FOLDER --out cloud.ply -q`` and
   ``python -m rangekit decode FOLDER --pattern FOLDER/patterns.json --out maps.npz -q``, wall seconds and the
   child's user + sys CPU seconds (``resource.getrusage``), one warm-up run of each command and tree first.

The machine may be shared: run nothing else heavy meanwhile and trust the pair ratios over single times.
``--markdown`` prints docs/benchmarks.md's tables (the progress goes to standard error).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]  # the repo (this is benchmarks/coded/bench_decode_vs.py)
BIG_PROJECTOR = (1920, 1080)


def _env(tree: Path) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(tree)
    return env


def build_folder(folder: Path, size: tuple[int, int]) -> None:
    """Render the Gray-code capture of the lumpy object at camera ``size`` into ``folder`` unless it is there."""
    if (folder / "patterns.json").exists() and (folder / "rig.json").exists():
        return
    folder.mkdir(parents=True, exist_ok=True)
    cmd = [sys.executable, "-m", "rangekit", "sim", "render", "--patterns", "graycode", "--object", "lumpy",
           "--seed", "0", "--out", str(folder), "--force", "-q"]
    if size != (1280, 1024):
        sys.path.insert(0, str(ROOT))
        from rangekit.rig.rig_file import save_rig
        from rangekit.sim.devices.sim_rig import default_rig

        rig = default_rig()
        rig = dataclasses.replace(rig, cameras=(rig.camera.resized(*size),),
                                  projector=rig.projector.resized(*BIG_PROJECTOR))
        rig_file = folder.parent / f"{folder.name}_rig.json"
        save_rig(rig, rig_file)
        cmd += ["--rig", str(rig_file)]
    print(f"rendering {folder} (once) ...", file=sys.stderr, flush=True)
    subprocess.run(cmd, check=True, env=_env(ROOT), stdout=sys.stderr)


# ---------------------------------------------------------------- the child: one tree, in process

def child(folder: Path, repeat: int) -> None:
    """Print one JSON line: the minimum wall seconds of each in-process call on ``folder``."""
    import numpy as np

    from rangekit.coded.decode import decode
    from rangekit.coded.reconstruct import reconstruct_view
    from rangekit.formats.capture import load_capture

    cap = load_capture(folder)
    rig, spec = cap.rig, cap.spec
    kw = dict(subpixel=True, full_scale=cap.full_scale, response=rig.projector_response)

    cpu = {}

    def best(fn, key: str) -> float:
        fn()                                  # numba's cache, first-call allocations
        walls, cpus = [], []
        for _ in range(repeat):
            t, c = time.perf_counter(), time.process_time()
            fn()
            walls.append(time.perf_counter() - t)
            cpus.append(time.process_time() - c)
        cpu[key + "_cpu"] = min(cpus)
        return min(walls)

    out = {"pixels": int(cap.images.shape[1] * cap.images.shape[2]), "frames": int(cap.images.shape[0])}
    out["decode"] = best(lambda: decode(cap.images, spec, **kw), "decode")
    out["decode_motion"] = best(lambda: decode(cap.images, spec, motion=True, **kw), "decode_motion")
    out["reconstruct_view"] = best(lambda: reconstruct_view(cap.images, spec, rig.camera, rig.projector, **kw),
                                   "reconstruct_view")
    try:
        from rangekit.rig.capture_check import check_rig
    except ImportError:
        check_rig = None
    if check_rig is not None:
        dec = decode(cap.images, spec, **kw)
        weak = dec.confidence < 0.03                      # reconstruct_view's default min_confidence
        cols = np.where(weak, np.nan, dec.proj_col)
        rows = np.where(weak, np.nan, dec.proj_row)
        out["check_rig"] = best(lambda: check_rig(rig.camera, rig.projector, cols, rows), "check_rig")
        out["check_rig_pixels"] = check_rig(rig.camera, rig.projector, cols, rows).n_pixels
    print(json.dumps({**out, **cpu}))


def run_child(tree: Path, folder: Path, repeat: int) -> dict:
    p = subprocess.run([sys.executable, __file__, "--child", str(folder), "--repeat", str(repeat)],
                       env=_env(tree), capture_output=True, text=True, cwd=str(tree))
    if p.returncode != 0:
        raise SystemExit(f"{tree}: the in-process run failed ({p.returncode}): {p.stderr[-2000:]}")
    return json.loads(p.stdout.strip().splitlines()[-1])


def run_cli(tree: Path, args: list[str]) -> tuple[float, float]:
    """(wall s, user + sys CPU s) of one ``python -m rangekit ARGS`` run from ``tree``."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    p = subprocess.run([sys.executable, "-m", "rangekit", *args], env=_env(tree), capture_output=True, text=True,
                       cwd=str(tree))
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        raise SystemExit(f"{tree}: rangekit {' '.join(args)} failed ({p.returncode}): {p.stderr[-2000:]}")
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


# ---------------------------------------------------------------- the parent: pairs and ratios

def pairs_of(new: Path, old: Path, n: int, run) -> list[tuple]:
    """``n`` pairs (new's result, old's result), the order swapped every pair."""
    out = []
    for i in range(n):
        if i % 2 == 0:
            a = run(new)
            b = run(old)
        else:
            b = run(old)
            a = run(new)
        out.append((a, b))
    return out


def ratio_row(label: str, a: list[float], b: list[float]) -> str:
    r = [x / y for x, y in zip(a, b)]
    return (f"| {label} | {min(a):.3f} | {min(b):.3f} | {min(a) / min(b):.3f} | {statistics.median(r):.3f} "
            f"({min(r):.3f}-{max(r):.3f}) |")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("old", type=Path, nargs="?", help="the other rangekit checkout")
    ap.add_argument("--pairs", type=int, default=5)
    ap.add_argument("--repeat", type=int, default=5, help="in-process calls per child (minimum taken)")
    ap.add_argument("--sizes", default="1280x1024,2048x1536", help="camera sizes, comma-separated WxH")
    ap.add_argument("--folder-root", type=Path, default=Path("/tmp/rangekit-bench/decode_vs"))
    ap.add_argument("--no-cli", action="store_true", help="skip the whole-process runs")
    ap.add_argument("--no-inprocess", action="store_true", help="skip the in-process runs")
    ap.add_argument("--markdown", action="store_true", help="print docs/benchmarks.md's tables only")
    ap.add_argument("--child", type=Path, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child is not None:
        child(a.child, a.repeat)
        return 0
    if a.old is None:
        ap.error("give OLD_TREE, the checkout to compare with")
    new, old = ROOT, a.old.resolve()
    say = (lambda *x: print(*x, file=sys.stderr, flush=True)) if a.markdown else \
        (lambda *x: print(*x, flush=True))
    sizes = [tuple(int(v) for v in s.lower().split("x")) for s in a.sizes.split(",")]
    folders = {s: a.folder_root / f"graycode_{s[0]}x{s[1]}" for s in sizes}
    for s, f in folders.items():
        build_folder(f, s)
    lines = [f"This tree {_commit(new)} against {_commit(old)}, {a.pairs} pairs (order swapped every pair); "
             "seconds are the minimum over the pairs, the ratios this / old.", ""]
    if not a.no_inprocess:
        lines += [f"| in process, min of {a.repeat} calls per child | this | old | ratio of minima | "
                  "pair ratios, median (range) |", "|---|---|---|---|---|"]
        checks = []
        for s, f in folders.items():
            say(f"in process {s[0]}x{s[1]}: {a.pairs} pairs ...")
            got = pairs_of(new, old, a.pairs, lambda tree: run_child(tree, f, a.repeat))
            for key, what in (("decode", "`decode`, subpixel (as reconstruct)"),
                              ("decode_motion", "`decode(motion=True)` (as `rangekit decode`)"),
                              ("reconstruct_view", "`reconstruct_view`")):
                for suffix, unit in (("", "wall s"), ("_cpu", "CPU s")):
                    row = ratio_row(f"{s[0]}x{s[1]} {what}, {unit}", [x[key + suffix] for x, _ in got],
                                    [y[key + suffix] for _, y in got])
                    lines.append(row)
                    say(row)
            if "check_rig" in got[0][0]:
                c, v = min(x["check_rig"] for x, _ in got), min(x["reconstruct_view"] for x, _ in got)
                cc, vc = min(x["check_rig_cpu"] for x, _ in got), min(x["reconstruct_view_cpu"] for x, _ in got)
                checks.append(f"{s[0]}x{s[1]}: `check_rig` {c * 1e3:.1f} ms wall of `reconstruct_view`'s "
                              f"{v * 1e3:.0f} ms ({c / v:.1%}), {cc * 1e3:.1f} of {vc * 1e3:.0f} CPU ms ({cc / vc:.1%}); "
                              f"{got[0][0]['check_rig_pixels']:,} pixels with both coordinates, 20,000 of them sampled")
                say(checks[-1])
        lines += [""] + [f"- {c}" for c in checks] + ([""] if checks else [])
    if not a.no_cli:
        lines += ["| whole process, min of the pairs | this | old | ratio of minima | pair ratios, median (range) |",
                  "|---|---|---|---|---|"]
        with tempfile.TemporaryDirectory(prefix="bench_decode_vs_") as tmp:
            for s, f in folders.items():
                cmds = {"reconstruct": ["reconstruct", str(f), "--out", str(Path(tmp) / "cloud.ply"), "-q"],
                        "decode": ["decode", str(f), "--pattern", str(f / "patterns.json"), "--out",
                                   str(Path(tmp) / "maps.npz"), "-q"]}
                for name, args in cmds.items():
                    say(f"whole process {s[0]}x{s[1]} rangekit {name}: warm-up + {a.pairs} pairs ...")
                    run_cli(new, args), run_cli(old, args)
                    got = pairs_of(new, old, a.pairs, lambda tree: run_cli(tree, args))
                    for k, unit in ((0, "wall s"), (1, "CPU s")):
                        row = ratio_row(f"{s[0]}x{s[1]} `rangekit {name}`, {unit}", [x[k] for x, _ in got],
                                        [y[k] for _, y in got])
                        lines.append(row)
                        say(row)
    if a.markdown:
        print("\n".join(lines).rstrip())
    return 0


def _commit(tree: Path) -> str:
    p = subprocess.run(["git", "-C", str(tree), "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    dirty = subprocess.run(["git", "-C", str(tree), "status", "--porcelain", "--untracked-files=no"],
                           capture_output=True, text=True).stdout.strip()
    return (p.stdout.strip() or str(tree)) + (" (modified)" if dirty else "")


if __name__ == "__main__":
    raise SystemExit(main())
