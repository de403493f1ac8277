"""Decoder speed: a 44-image Gray-code stack at 2048x1500, rangekit side by side with OpenCV contrib.

    bash benchmarks/coded/setup_opencv_contrib.sh          # once: the OpenCV contrib peer's own venv
    .venv/bin/python benchmarks/coded/bench_decode.py [--repeat 5] [--max-pixels N] [--cv-black-threshold 10]
                                                      [--no-opencv] [--rebuild] [--markdown]

``--markdown`` prints docs/benchmarks.md's table and target sentence only (a ``make docs-figures`` block;
the rest goes to standard error, and the exit status is 0 whether or not a target is met).

The stack is OpenCV's own 44 images (``cv2.structured_light.GrayCodePattern`` for a 1280x800 projector:
11 column pattern/inverse pairs MSB first, 10 row pairs, white, black; generated in the peer venv so the
bytes are OpenCV's) rendered by the simulator on the default rig with its camera resized to 2048x1500,
the lumpy object, ``ImagingModel(full_well=5000)`` (about 1 % noise). It is cached with its ground truth
in ``--cache-dir`` (default /tmp/rangekit-bench), so reruns skip the rendering.

Stages: reading the stack once from memory (the floor for any decoder), loading the 44 PNGs on two
threads, rangekit's ``decode`` (integer codes + confidence, then subpixel on both axes; median of
``--repeat`` runs on the in-memory stack), and the OpenCV peer (``benchmarks/coded/_opencv_peer.py``, run in
.venv-bench, one process per mode): ``getprojpixel``, the one-camera way (shadow mask, then
``getProjPixel`` per pixel in Python), and ``decode-stereo``, OpenCV's C++ ``decode()`` given the same
images as both cameras (it decodes two views and builds a disparity map; it yields no projector codes).
OpenCV only decodes pixels past its shadow mask (|white - black| > blackThreshold), so its time scales
with that count. Its default threshold, 40, drops about half the lit pixels of this dim scene; the peer
therefore runs at the default and at ``--cv-black-threshold`` (default 10, which keeps ~99 % of the lit
pixels and no unlit ones), and rangekit is compared with the latter: the same pixels decoded.

Accuracy is measured on the pixels the projector lights (ground truth ``lit``): "col ok" / "row ok" is
the fraction of them decoded to within half a projector pixel of the truth (integer decodes must equal
``floor(true + 0.5)``; failures count as wrong); "col RMS" is over valid lit pixels within 1 px of truth.

Targets (exit status 1 if one is missed, checked only when ``rangekit.coded.decode`` exists): integer columns
and rows with confidence in <= 0.05 s and >= 30x faster than OpenCV, where "OpenCV" is its fastest
one-camera time at the matched threshold, min(getprojpixel, decode-stereo / 2); subpixel on both axes in <= 0.1 s.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]  # the repo (this is benchmarks/coded/bench_decode.py)
PEER = ROOT / "benchmarks" / "coded" / "_opencv_peer.py"
SETUP = ROOT / "benchmarks" / "coded" / "setup_opencv_contrib.sh"
BENCH_VENV = ROOT / ".venv-bench"
CAM_W, CAM_H = 2048, 1500
PROJ_W, PROJ_H = 1280, 800
FULL_WELL = 5000.0
SCENE = "lumpy"
SEED = 0

TARGET_INT_S = 0.05
TARGET_INT_SPEEDUP = 30.0
TARGET_SUBPIX_S = 0.1


# ------------------------------------------------------------------ OpenCV peer venv
def peer_python(*, allow_setup: bool) -> Path | None:
    """The .venv-bench interpreter, creating the venv if missing; None (with a message) if impossible."""
    py = BENCH_VENV / "bin" / "python"
    probe = [str(py), "-c", "import cv2; cv2.structured_light.GrayCodePattern.create"]
    if py.exists() and subprocess.run(probe, capture_output=True).returncode == 0:
        return py
    if not allow_setup:
        return None
    print(f"OpenCV contrib venv missing: running {SETUP.relative_to(ROOT)}", flush=True)
    done = subprocess.run(["bash", str(SETUP)], capture_output=True, text=True)
    if done.returncode != 0 or subprocess.run(probe, capture_output=True).returncode != 0:
        print(f"could not create {BENCH_VENV} (rc {done.returncode}): {(done.stderr or done.stdout)[-500:]}")
        print("skipping the OpenCV peer")
        return None
    return py


def run_peer(py: Path, *args: str, timeout: float = 3600) -> subprocess.CompletedProcess:
    return subprocess.run([str(py), str(PEER), *args], capture_output=True, text=True, timeout=timeout)


# ------------------------------------------------------------------ test stack
def opencv_order_from_rangekit() -> np.ndarray:
    """rangekit's Gray-code frames (white, black, pairs) reordered as OpenCV's (pairs, white, black)."""
    from rangekit.coded.patterns import make_pattern_spec

    frames = list(make_pattern_spec("graycode", (PROJ_W, PROJ_H)).frames())
    return np.stack(frames[2:] + frames[:2])


def load_patterns(cache: Path, py: Path | None) -> tuple[np.ndarray, str]:
    """OpenCV's 44 pattern images (from the peer venv), checked against rangekit's frames in that order."""
    ours = opencv_order_from_rangekit()
    if py is None:
        return ours, "rangekit's frames in OpenCV's order (OpenCV peer not used)"
    path = cache / f"opencv_patterns_{PROJ_W}x{PROJ_H}.npy"
    if not path.exists():
        done = run_peer(py, "--generate-patterns", str(path), "--projector", f"{PROJ_W}x{PROJ_H}")
        if done.returncode != 0:
            sys.exit(f"generating OpenCV's patterns failed: {done.stderr[-1000:]}")
    pats = np.load(path)
    same = pats.shape == ours.shape and np.array_equal(pats, ours)
    return pats, f"OpenCV's own generate() + getImagesForShadowMasks(); identical to rangekit's frames: {same}"


def build_stack(cache: Path, patterns: np.ndarray, *, rebuild: bool) -> tuple[np.ndarray, dict, float | None]:
    """The rendered (44, H, W) uint8 stack and its truth, from the cache when its recipe matches."""
    recipe = {"camera": [CAM_W, CAM_H], "projector": [PROJ_W, PROJ_H], "scene": SCENE, "full_well": FULL_WELL,
              "seed": SEED, "patterns_sha1": hashlib.sha1(patterns.tobytes()).hexdigest()}
    stem = cache / f"stack_{CAM_W}x{CAM_H}"
    stack_path, truth_path, meta_path = stem.with_suffix(".npy"), stem.with_suffix(".truth.npz"), stem.with_suffix(".json")
    if not rebuild and meta_path.exists() and stack_path.exists() and truth_path.exists():
        if json.loads(meta_path.read_text()) == recipe:
            with np.load(truth_path) as t:
                truth = {k: t[k] for k in t.files}
            return np.load(stack_path), truth, None

    from rangekit.rig.rig_file import Rig
    from rangekit.sim import ImagingModel, SimRig, default_rig, default_scene

    t0 = time.perf_counter()
    base = default_rig()
    rig = Rig(cameras=(base.camera.resized(CAM_W, CAM_H),), projector=base.projector,
              T_world_table=base.T_world_table)
    sim = SimRig(default_scene(SCENE), rig, imaging=ImagingModel(full_well=FULL_WELL), seed=SEED)
    stack = np.stack(sim.capture_sequence(list(patterns)))
    gt = sim.ground_truth()
    truth = {"proj_col": gt.proj_col, "proj_row": gt.proj_row, "lit": gt.lit}
    t_build = time.perf_counter() - t0

    # Write to temporary names, rename last: an interrupted run never leaves a stale cache.
    for path, save in ((stack_path, lambda f: np.save(f, stack)), (truth_path, lambda f: np.savez(f, **truth))):
        tmp = path.with_name(path.name + ".tmp")
        with open(tmp, "wb") as f:
            save(f)
        os.replace(tmp, path)
    meta_path.write_text(json.dumps(recipe))
    for png in (cache / f"png_{CAM_W}x{CAM_H}").glob("*.png"):
        png.unlink()
    return stack, truth, t_build


def write_pngs(cache: Path, stack: np.ndarray) -> list[Path]:
    import cv2

    folder = cache / f"png_{CAM_W}x{CAM_H}"
    folder.mkdir(exist_ok=True)
    paths = [folder / f"{i:03d}.png" for i in range(len(stack))]
    for path, img in zip(paths, stack):
        if not path.exists():
            tmp = path.with_name("tmp_" + path.name)
            if not cv2.imwrite(str(tmp), img):
                sys.exit(f"cv2.imwrite failed for {tmp}")
            os.replace(tmp, path)
    return paths


# ------------------------------------------------------------------ timing and accuracy
def median_time(fn, repeat: int, warmup: int = 10) -> tuple[float, float, object]:
    """(median of ``repeat`` calls after ``warmup`` untimed ones, first call, last result).

    The first calls load the compiled kernels from numba's cache, start its thread pool and page-fault
    in ~150 MB of fresh output arrays; a scan decoding many views runs at the steady-state time.
    """
    t = time.perf_counter()
    out = fn()
    first = time.perf_counter() - t
    for _ in range(max(0, warmup - 1)):
        fn()
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return float(np.median(times)), first, out


def accuracy(col, row, truth: dict, *, integer: bool, where: np.ndarray | None = None) -> dict:
    """Fractions of lit pixels decoded within half a projector pixel, and the column RMS on inliers."""
    lit = truth["lit"] if where is None else truth["lit"] & where
    n = max(int(lit.sum()), 1)
    out = {"n": int(lit.sum())}
    for name, dec, true in (("col", col, truth["proj_col"]), ("row", row, truth["proj_row"])):
        if dec is None:
            continue
        dec = np.asarray(dec, np.float64)
        valid = lit & np.isfinite(dec) & (dec >= 0)
        err = np.where(valid, dec - np.where(lit, true, 0.0), np.inf)
        ok = (dec == np.floor(true + 0.5)) & valid if integer else np.abs(err) <= 0.5
        out[f"{name}_ok"] = float(np.count_nonzero(ok & lit)) / n
        out[f"{name}_valid"] = float(np.count_nonzero(valid)) / n
        inl = np.abs(err) <= 1.0
        out[f"{name}_rms"] = float(np.sqrt(np.mean(err[inl] ** 2))) if inl.any() else float("nan")
    return out


def fmt_acc(acc: dict | None) -> str:
    if not acc or "col_ok" not in acc:
        return f"{'n/a':>7} {'n/a':>7} {'n/a':>8}"
    row = f"{acc['row_ok']:7.2%}" if "row_ok" in acc else f"{'n/a':>7}"
    return f"{acc['col_ok']:7.2%} {row} {acc['col_rms']:8.3f}"


def run_opencv(py: Path, stack_path: Path, cache: Path, truth: dict, *, black_threshold: int,
               max_pixels: int | None, stereo_repeat: int) -> dict:
    """Both peer modes at one shadow threshold, one process per mode (a crash cannot take the other down)."""
    out = {"version": None, "modes": {}, "rows": [], "one_camera": None}
    times = []
    for mode, extra in (("getprojpixel", [] if max_pixels is None else ["--max-pixels", str(max_pixels)]),
                        ("decode-stereo", ["--repeat", str(stereo_repeat)])):
        npz = cache / f"opencv_{mode}_black{black_threshold}.npz"
        print(f"running OpenCV peer: {mode}, black threshold {black_threshold} ...", flush=True)
        t = time.perf_counter()
        done = run_peer(py, str(stack_path), str(npz), "--mode", mode, "--black-threshold", str(black_threshold),
                        *extra)
        wall = time.perf_counter() - t
        if done.returncode != 0:
            out["modes"][mode] = f"FAILED (exit {done.returncode}): {(done.stderr or done.stdout).strip()[-300:]}"
            continue
        out["modes"][mode] = f"works ({wall:.1f} s wall)"
        with np.load(npz) as r:
            out["version"] = str(r["opencv_version"])
            secs = float(r["seconds"])
            if mode == "getprojpixel":
                note = (f"extrapolated from {int(r['n_sampled'])} px ({float(r['seconds_measured']):.1f} s)"
                        if bool(r["extrapolated"]) else "all pixels")
                note += f"; {int((~r['shadow']).sum())} past the shadow mask"
                acc = accuracy(r["proj_col"], r["proj_row"], truth, integer=True, where=r["sampled"])
                out["rows"].append(("OpenCV getProjPixel loop", secs, note, acc))
                times.append(secs)
            else:
                out["rows"].append(("OpenCV decode() 2 cams", secs,
                                    f"median of {len(r['seconds_runs'])}; no projector codes", None))
                out["rows"].append(("  ... / 2 per camera", secs / 2, "estimate; includes half the matching", None))
                times.append(secs / 2)
    out["one_camera"] = min(times) if times else None
    return out


# ------------------------------------------------------------------ docs/benchmarks.md's block
def markdown(rows: list, t_cv: float | None, t_int: float, t_sub: float, first: float, black: int,
             repeat: int) -> str:
    """The table of docs/benchmarks.md (the OpenCV rows at the matched shadow threshold) and the targets."""
    def pct(acc):
        return "" if not acc or "col_ok" not in acc else f"{acc['col_ok']:.1%}"

    def rms(acc):
        return "" if not acc or "col_rms" not in acc else f"{acc['col_rms']:.3f} px"

    by = {stage: (secs, acc) for stage, secs, _, acc in rows}
    lines = ["| stage | time | vs OpenCV | lit pixels within 0.5 px (columns) | column RMS |", "|---|---|---|---|---|",
             f"| read the stack once (memory floor) | {by['read stack once (sum)'][0]:.3f} s | | | |",
             f"| load the 44 PNGs, 2 threads (reported separately) | {by['load 44 PNGs (2 threads)'][0]:.2f} s | | | |"]
    for stage, label in (("rangekit integer col+row+conf", "rangekit integer column + row + confidence"),
                         ("rangekit subpixel col+row", "rangekit subpixel edges, both axes")):
        secs, acc = by[stage]
        ratio = f"{t_cv / secs:.1f}x" if t_cv else "(no peer)"
        lines.append(f"| **{label}** | **{secs:.3f} s** | {ratio} | {pct(acc)} | {rms(acc)} |")
    peer = ((f"OpenCV getProjPixel loop, black {black}", "OpenCV `getProjPixel` loop over every pixel "
             "(its single-camera API)"), (f"  ... / 2 per camera, black {black}",
                                          "OpenCV `decode()` (C++, two cameras) / 2"))
    for stage, label in peer:
        if stage in by:
            secs, acc = by[stage]
            lines.append(f"| {label} | {secs:.2f} s | 1/{secs / t_int:.0f} | {pct(acc) or '(no codes)'} | {rms(acc)} |")
    met = t_int <= TARGET_INT_S and t_sub <= TARGET_SUBPIX_S and (t_cv is None or t_cv / t_int >= TARGET_INT_SPEEDUP)
    peer_note = (f"{t_cv / t_int:.1f}x OpenCV's faster figure" if t_cv else "the OpenCV peer was not run")
    lines += ["", f"Targets: integer <= {TARGET_INT_S} s and >= {TARGET_INT_SPEEDUP:.0f}x OpenCV, subpixel <= "
              f"{TARGET_SUBPIX_S} s: {'met' if met else 'not met'} in this run (integer {t_int:.3f} s, {peer_note}; "
              f"median of {repeat} after 10 warm-up calls; the first call in the process took {first:.2f} s)."]
    return "\n".join(lines)


# ------------------------------------------------------------------ main
def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeat", type=int, default=5, help="timed runs of each rangekit stage (median reported)")
    ap.add_argument("--max-pixels", type=int, default=None,
                    help="OpenCV getprojpixel: time N random pixels and extrapolate (default: every pixel)")
    ap.add_argument("--stereo-repeat", type=int, default=3, help="OpenCV decode-stereo runs (median)")
    ap.add_argument("--cv-black-threshold", type=int, default=10,
                    help="OpenCV shadow threshold for the compared run (it also runs its default, 40)")
    ap.add_argument("--no-opencv", action="store_true", help="skip the OpenCV peer")
    ap.add_argument("--cache-dir", type=Path, default=Path("/tmp/rangekit-bench"))
    ap.add_argument("--rebuild", action="store_true", help="render the stack again even if cached")
    ap.add_argument("--markdown", action="store_true", help="print docs/benchmarks.md's table only")
    args = ap.parse_args()
    out = sys.stdout
    if args.markdown:
        sys.stdout = sys.stderr  # the human report goes to stderr, the block to stdout
    cache = args.cache_dir
    cache.mkdir(parents=True, exist_ok=True)
    repeat = max(1, args.repeat)

    # (i) the test stack: OpenCV's patterns, rendered once and cached
    py = None if args.no_opencv else peer_python(allow_setup=True)
    patterns, pattern_note = load_patterns(cache, py)
    stack, truth, t_build = build_stack(cache, patterns, rebuild=args.rebuild)
    assert stack.shape == (44, CAM_H, CAM_W) and stack.dtype == np.uint8, stack.shape
    stack_path = cache / f"stack_{CAM_W}x{CAM_H}.npy"
    n_lit = int(truth["lit"].sum())
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"python {platform.python_version()}, numpy {np.__version__}")
    print(f"stack: 44 x {CAM_W}x{CAM_H} uint8 ({stack.nbytes / 1e6:.0f} MB), projector {PROJ_W}x{PROJ_H}, "
          f"scene {SCENE!r}, full_well {FULL_WELL:g}; {n_lit} lit pixels ({n_lit / truth['lit'].size:.1%})")
    print(f"patterns: {pattern_note}")
    print(f"stack {'rendered in %.1f s' % t_build if t_build is not None else 'loaded from cache'}: {stack_path}")

    rows = []  # (stage, seconds, note, accuracy dict or None)
    firsts = {}

    # (ii) memory floor: read every byte once
    t_read, _, _ = median_time(lambda: stack.sum(dtype=np.uint64), repeat)
    rows.append(("read stack once (sum)", t_read, "memory floor", None))

    # (iii) load the PNGs on two threads (files written once; page cache warm)
    import cv2

    pngs = write_pngs(cache, stack)

    def load_pngs():
        with ThreadPoolExecutor(max_workers=2) as pool:
            return list(pool.map(lambda p: cv2.imread(str(p), cv2.IMREAD_UNCHANGED), pngs))

    t_png, _, imgs = median_time(load_pngs, repeat)
    assert all(a is not None and np.array_equal(a, b) for a, b in zip(imgs, stack)), "PNG round trip differs"
    del imgs
    rows.append(("load 44 PNGs (2 threads)", t_png, "warm page cache", None))

    # (iv) rangekit's decoder
    have_decode = True
    try:
        from rangekit.coded.decode import decode
        from rangekit.coded.patterns import make_pattern_spec
    except ImportError as exc:
        have_decode = False
        print(f"rangekit.coded.decode not available yet ({exc}); skipping the rangekit decoder")
    t_int = t_sub = None
    if have_decode:
        spec = make_pattern_spec("graycode", (PROJ_W, PROJ_H))
        t_int, first, res = median_time(lambda: decode(stack, spec, order="opencv", subpixel=False), repeat)
        firsts["int"] = first
        rows.append(("rangekit integer col+row+conf", t_int, f"first call {first:.3f} s",
                     accuracy(res.proj_col, res.proj_row, truth, integer=True)))
        t_sub, first, res = median_time(lambda: decode(stack, spec, order="opencv", subpixel=True), repeat)
        rows.append(("rangekit subpixel col+row", t_sub, f"first call {first:.3f} s",
                     accuracy(res.proj_col, res.proj_row, truth, integer=False)))
        del res

    # (v) the OpenCV peer: its default thresholds, and a shadow threshold that keeps the lit pixels
    cv_version, modes_ok, t_cv = None, {}, None
    if py is not None:
        settings = [("defaults", 40)]
        if args.cv_black_threshold != 40:
            settings.append(("matched", args.cv_black_threshold))
        for label, black in settings:
            res = run_opencv(py, stack_path, cache, truth, black_threshold=black, max_pixels=args.max_pixels,
                             stereo_repeat=max(1, args.stereo_repeat))
            cv_version = res["version"] or cv_version
            modes_ok.update({f"{m} (black {black})": v for m, v in res["modes"].items()})
            for stage, secs, note, acc in res["rows"]:
                rows.append((f"{stage}, black {black}", secs, note, acc))
            if res["one_camera"] is not None:
                t_cv = res["one_camera"]  # the last setting (matched, if run) is the one compared against
                t_cv_label = f"black threshold {black} ({label})"

    # table
    print()
    if t_cv is not None:
        print(f"OpenCV {cv_version} contrib structured_light. 'vs OpenCV' = {t_cv:.3f} s / stage time, where "
              f"{t_cv:.3f} s is OpenCV's one-camera time at {t_cv_label}:\n  the faster of the getProjPixel "
              f"loop and decode-stereo / 2")
    print(f"{'stage':36s} {'time':>9s} {'vs OpenCV':>10s} {'col ok':>7s} {'row ok':>7s} {'col RMS':>8s}  note")
    for stage, secs, note, acc in rows:
        ratio = f"{t_cv / secs:9.1f}x" if t_cv else f"{'n/a':>10s}"
        print(f"{stage:36s} {secs:8.3f}s {ratio} {fmt_acc(acc)}  {note}")
    if modes_ok:
        print("OpenCV modes: " + "; ".join(f"{m}: {s}" for m, s in modes_ok.items()))
    print("accuracy on lit pixels: ok = within 0.5 projector px (integer: equals floor(truth + 0.5)); "
          "col RMS over valid lit pixels within 1 px")

    if args.markdown:
        out.write(markdown(rows, t_cv, t_int, t_sub, firsts.get("int"), args.cv_black_threshold, repeat) + "\n")
        return 0
    # targets
    if not have_decode:
        print("targets not checked: rangekit.coded.decode not available yet")
        return 0
    checks = [(f"integer col+row+conf <= {TARGET_INT_S} s", t_int <= TARGET_INT_S),
              (f"subpixel col+row <= {TARGET_SUBPIX_S} s", t_sub <= TARGET_SUBPIX_S)]
    if t_cv is not None:
        checks.append((f"integer >= {TARGET_INT_SPEEDUP:.0f}x faster than OpenCV ({t_cv / t_int:.1f}x)",
                       t_cv / t_int >= TARGET_INT_SPEEDUP))
    else:
        print(f"target not checked: >= {TARGET_INT_SPEEDUP:.0f}x faster than OpenCV (peer unavailable)")
    for name, ok in checks:
        print(f"{'PASS' if ok else 'FAIL'}: {name}")
    return 0 if all(ok for _, ok in checks) else 1


if __name__ == "__main__":
    sys.exit(main())
