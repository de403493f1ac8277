"""``rangekit decode`` from the command line on a 46-image 2048x1500 Gray-code folder, in CPU seconds.

    PYTHONPATH=. python benchmarks/coded/bench_decode_cli.py [--folder DIR] [--repeat 3] [--importtime] [--markdown]

The folder is rendered once by ``rangekit sim render --patterns graycode`` on the default rig with its camera
resized to 2048x1500 and its projector to 1920x1080 (11 column and 11 row bit pairs + white + black = 46
images; lumpy object, seed 0) into ``--folder`` (default /tmp/rangekit-bench/decode_cli_2048x1500), reused
when it is there. Then ``python -m rangekit decode FOLDER --pattern FOLDER/patterns.json --out maps.npz``
runs ``--repeat`` times as a subprocess, alternating with the same command with ``--compress``: start-up, imports, reading the PNGs, decoding (subpixel on both
axes) and writing the maps. Printed: the user + sys CPU seconds of each run (``resource.getrusage`` of the
child; the machine may be shared, so CPU not wall) and the minimum. ``--importtime`` also prints the ten
slowest imports of one run (``python -X importtime``); ``--code TREE`` times another checkout (before/after).
``--markdown`` prints docs/benchmarks.md's row and target sentence only (a ``make docs-figures`` block).

Target (set with the speed targets of rangekit process): <= 2 CPU-s.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]  # the repo (this is benchmarks/ROOM/SCRIPT.py)
CODE = ROOT  # the rangekit tree the CLI runs from (--code)
CAM, PROJ = (2048, 1500), (1920, 1080)
TARGET_CPU_S = 2.0


def _env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(CODE) + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def build_folder(folder: Path) -> None:
    """Render the 46-image capture into ``folder`` unless its 46 PNGs are there."""
    if len(list(folder.glob("[0-9][0-9][0-9].png"))) == 46 and (folder / "patterns.json").exists():
        return
    sys.path.insert(0, str(ROOT))
    from rangekit.rig.rig_file import save_rig
    from rangekit.sim.devices.sim_rig import default_rig

    rig = default_rig()
    rig = dataclasses.replace(rig, cameras=(rig.camera.resized(*CAM),), projector=rig.projector.resized(*PROJ))
    folder.mkdir(parents=True, exist_ok=True)
    rig_file = folder.parent / (folder.name + "_rig.json")
    save_rig(rig, rig_file)
    print(f"rendering {folder} (once) ...", file=sys.stderr, flush=True)
    subprocess.run([sys.executable, "-m", "rangekit", "sim", "render", "--rig", str(rig_file), "--patterns",
                    "graycode", "--object", "lumpy", "--seed", "0", "--out", str(folder)], check=True, env=_env(),
                   stdout=sys.stderr)


def run_cli(folder: Path, out: Path, extra: list[str] = (), options: list[str] = ()) -> tuple[float, float, str]:
    """(CPU-s user + sys, wall s, stderr) of one ``rangekit decode [options]`` subprocess (``extra``: python's)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    p = subprocess.run([sys.executable, *extra, "-m", "rangekit", "decode", str(folder), "--pattern",
                        str(folder / "patterns.json"), *options, "--out", str(out), "--force"], env=_env(),
                       capture_output=True,
                       text=True)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if p.returncode != 0:
        raise SystemExit(f"rangekit decode failed ({p.returncode}): {p.stderr[-2000:]}")
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, wall, p.stderr


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--folder", type=Path, default=Path("/tmp/rangekit-bench/decode_cli_2048x1500"))
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--importtime", action="store_true")
    ap.add_argument("--code", type=Path, default=ROOT, help="rangekit tree to time (default: this one)")
    ap.add_argument("--markdown", action="store_true", help="print docs/benchmarks.md's block only")
    a = ap.parse_args()
    say = (lambda *x: print(*x, file=sys.stderr)) if a.markdown else print
    global CODE
    CODE = a.code
    build_folder(a.folder)
    n = len(list(a.folder.glob("[0-9][0-9][0-9].png")))
    with tempfile.TemporaryDirectory(prefix="bench_decode_cli_") as tmp:
        out = Path(tmp) / "maps.npz"
        run_cli(a.folder, out)  # warm the page cache and numba's on-disk cache
        cpus, walls, packed, stored_mb = [], [], [], 0.0
        for r in range(a.repeat):       # the default (maps.npz stored) and --compress, alternating
            out.unlink(missing_ok=True)
            cpu, wall, _ = run_cli(a.folder, out)
            cpus.append(cpu)
            walls.append(wall)
            stored_mb = out.stat().st_size / 1e6
            say(f"run {r + 1}: {cpu:.2f} CPU-s, {wall:.2f} s wall, {stored_mb:.1f} MB")
            out.unlink()
            packed.append(run_cli(a.folder, out, options=["--compress"])[:2] + (out.stat().st_size / 1e6,))
            say(f"run {r + 1} --compress: {packed[-1][0]:.2f} CPU-s, {packed[-1][1]:.2f} s wall, "
                f"{packed[-1][2]:.1f} MB")
        if a.importtime:
            out.unlink(missing_ok=True)
            _, _, err = run_cli(a.folder, out, ["-X", "importtime"])
            rows = []
            for line in err.splitlines():
                if line.startswith("import time:") and "|" in line:
                    parts = [s.strip() for s in line[len("import time:"):].split("|")]
                    if parts[1].isdigit():
                        rows.append((int(parts[1]), parts[2]))
            print("slowest imports (cumulative us):")
            for us, name in sorted(rows, reverse=True)[:10]:
                print(f"  {us / 1e6:6.3f} s  {name}")
    best = min(cpus)
    if a.markdown:
        print(f"| `make docs-figures` run | whole command, CPU s (min of {a.repeat}) | wall s (min of {a.repeat}) "
              f"| maps.npz |\n|---|---|---|---|")
        print(f"| default (maps.npz stored, as `np.savez`) | {best:.2f} | {min(walls):.2f} | {stored_mb:.1f} MB |")
        print(f"| `--compress` (deflate level 1) | {min(p[0] for p in packed):.2f} | {min(p[1] for p in packed):.2f} "
              f"| {packed[-1][2]:.1f} MB |\n")
        print(f"Target <= {TARGET_CPU_S:g} CPU-s: {'met' if best <= TARGET_CPU_S else 'not met'} in this run.")
        return
    print(f"rangekit decode of {n} images {CAM[0]}x{CAM[1]}: {best:.2f} CPU-s (min of {a.repeat}); "
          f"target <= {TARGET_CPU_S} CPU-s: {'met' if best <= TARGET_CPU_S else 'MISSED'}")


if __name__ == "__main__":
    main()
