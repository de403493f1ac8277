"""OpenCV contrib's Gray-code decoder, timed: the peer of bench_decode.py. Runs inside .venv-bench.

Only numpy and cv2 (opencv-contrib-python-headless) are imported, so it runs in the separate venv made
by ``benchmarks/coded/setup_opencv_contrib.sh`` (contrib and opencv-python-headless both provide ``cv2``)::

    .venv-bench/bin/python benchmarks/coded/_opencv_peer.py --generate-patterns PATTERNS.npy [--projector 1280x800]
    .venv-bench/bin/python benchmarks/coded/_opencv_peer.py STACK.npy OUT.npz --mode getprojpixel [--max-pixels N]
    .venv-bench/bin/python benchmarks/coded/_opencv_peer.py STACK.npy OUT.npz --mode decode-stereo
    .venv-bench/bin/python benchmarks/coded/_opencv_peer.py --check

Stack order (``cv2.structured_light.GrayCodePattern``, checked by ``--check``): for a W x H projector,
ceil(log2 W) column (vertical-stripe) pattern/inverse pairs, most significant bit first, then ceil(log2 H)
row pairs, then white, then black. 1280x800 gives 2 * (11 + 10) + 2 = 44 images. Pattern image 2k holds
bit (n - 1 - k) of gray(u) = u ^ (u >> 1) as 255/0; image 2k + 1 is its inverse. White and black are
what ``getImagesForShadowMasks`` returns (note that it takes and returns them as (black, white)).

Modes
-----
``getprojpixel``: the one-camera way. Shadow mask as OpenCV's own ``decode`` computes it
(``|white - black| > blackThreshold``, default 40), then ``getProjPixel(patterns, x, y)`` in a Python
loop for every unshadowed pixel. ``getProjPixel`` returns True on *failure* (some pattern/inverse
difference below ``whiteThreshold``, default 5, or a code outside the projector). ``--max-pixels N``
decodes a random subset of N pixels and extrapolates the loop time to the whole image (reported).
``decode-stereo``: ``decode()``, the only vectorised (C++) entry point, with the same images given as
both cameras. It decodes both views and matches them into a disparity map; it gives no projector
coordinates. With one camera (or without black/white images) it segfaults in OpenCV 5.0.0.

OUT.npz holds ``proj_col``, ``proj_row`` (H, W) int32, -1 where OpenCV reports failure or shadow
(getprojpixel only), ``sampled`` (H, W) bool, ``seconds`` (whole image, extrapolated if ``extrapolated``),
``seconds_runs`` and the settings.
"""

from __future__ import annotations

import argparse
import json
import sys
import time

import cv2
import numpy as np

MODES = ("getprojpixel", "decode-stereo")


def _structured_light():
    sl = getattr(cv2, "structured_light", None)
    if sl is None:
        sys.exit(f"cv2 {cv2.__version__} at {cv2.__file__} has no structured_light module: "
                 "install opencv-contrib-python-headless (benchmarks/coded/setup_opencv_contrib.sh)")
    return sl


def make_graycode(width: int, height: int, *, white_threshold: int | None = None,
                  black_threshold: int | None = None):
    gp = _structured_light().GrayCodePattern.create(width, height)
    if white_threshold is not None:
        gp.setWhiteThreshold(int(white_threshold))
    if black_threshold is not None:
        gp.setBlackThreshold(int(black_threshold))
    return gp


def opencv_patterns(width: int, height: int) -> np.ndarray:
    """(n + 2, height, width) uint8: OpenCV's pattern images, then white, then black."""
    gp = make_graycode(width, height)
    ok, patterns = gp.generate()
    if not ok:
        sys.exit("GrayCodePattern.generate() failed")
    black, white = gp.getImagesForShadowMasks(None, None)
    return np.stack(list(patterns) + [white, black])


def expected_patterns(width: int, height: int) -> np.ndarray:
    """The order described in the module docstring, built independently of OpenCV."""
    def bit_planes(n: int) -> list[np.ndarray]:
        nbits = int(np.ceil(np.log2(n)))
        x = np.arange(n)
        g = x ^ (x >> 1)
        out = []
        for b in range(nbits - 1, -1, -1):
            line = ((g >> b) & 1).astype(np.uint8) * 255
            out += [line, 255 - line]
        return out
    frames = [np.broadcast_to(c[None, :], (height, width)) for c in bit_planes(width)]
    frames += [np.broadcast_to(r[:, None], (height, width)) for r in bit_planes(height)]
    frames += [np.full((height, width), 255, np.uint8), np.zeros((height, width), np.uint8)]
    return np.stack(frames)


def shadow_mask(white: np.ndarray, black: np.ndarray, black_threshold: int) -> np.ndarray:
    """OpenCV's computeShadowMasks: |white - black| > blackThreshold (as doubles)."""
    return np.abs(white.astype(np.int16) - black.astype(np.int16)) > black_threshold


def run_getprojpixel(stack: np.ndarray, gp, n_patterns: int, black_threshold: int, *,
                     max_pixels: int | None, seed: int) -> dict:
    H, W = stack.shape[1:]
    patterns = [stack[i] for i in range(n_patterns)]
    white, black = stack[n_patterns], stack[n_patterns + 1]
    n_total = H * W
    if max_pixels is not None and max_pixels < n_total:
        flat = np.sort(np.random.default_rng(seed).choice(n_total, size=max_pixels, replace=False))
    else:
        flat = None

    t0 = time.perf_counter()
    # Shadow mask (vectorised, as a Python user would write it), then one getProjPixel call per pixel.
    mask = shadow_mask(white, black, black_threshold)
    t_mask = time.perf_counter() - t0
    t1 = time.perf_counter()
    if flat is None:
        ys, xs = np.nonzero(mask)
    else:
        keep = mask.ravel()[flat]
        ys, xs = np.divmod(flat[keep], W)
    cols, rows = [], []
    get = gp.getProjPixel
    for y, x in zip(ys.tolist(), xs.tolist()):
        err, (px, py) = get(patterns, x, y)
        if err:
            px = py = -1
        cols.append(px)
        rows.append(py)
    t_loop = time.perf_counter() - t1

    proj_col = np.full((H, W), -1, np.int32)
    proj_row = np.full((H, W), -1, np.int32)
    proj_col[ys, xs] = cols
    proj_row[ys, xs] = rows
    sampled = np.ones((H, W), bool)
    if flat is not None:
        sampled = np.zeros(H * W, bool)
        sampled[flat] = True
        sampled = sampled.reshape(H, W)
    n_sampled = int(sampled.sum())
    scale = n_total / n_sampled
    return {"proj_col": proj_col, "proj_row": proj_row, "sampled": sampled, "shadow": ~mask,
            "seconds": t_mask + t_loop * scale, "seconds_measured": t_mask + t_loop,
            "seconds_shadow_mask": t_mask, "seconds_loop_measured": t_loop,
            "seconds_runs": np.array([t_mask + t_loop * scale]), "extrapolated": flat is not None,
            "n_sampled": n_sampled, "n_calls": len(cols), "has_codes": True, "is_stereo": False}


def run_decode_stereo(stack: np.ndarray, gp, n_patterns: int, *, repeat: int) -> dict:
    patterns = [stack[i] for i in range(n_patterns)]
    white, black = stack[n_patterns], stack[n_patterns + 1]
    runs = []
    for _ in range(repeat):
        t = time.perf_counter()
        ok, disparity = gp.decode([patterns, patterns], None, [black, black], [white, white])
        runs.append(time.perf_counter() - t)
        if not ok:
            sys.exit("GrayCodePattern.decode() returned False")
    return {"seconds": float(np.median(runs)), "seconds_runs": np.array(runs), "extrapolated": False,
            "has_codes": False, "is_stereo": True, "n_disparity_nonzero": int(np.count_nonzero(disparity)),
            "disparity_shape": tuple(int(n) for n in disparity.shape)}


def check(width: int, height: int) -> int:
    """Verify the pattern order and that getProjPixel inverts the patterns; decode-stereo on a crop."""
    got = opencv_patterns(width, height)
    ours = expected_patterns(width, height)
    order_ok = got.shape == ours.shape and np.array_equal(got, ours)
    print(f"OpenCV {cv2.__version__}: GrayCodePattern.create({width}, {height}) -> "
          f"{got.shape[0] - 2} pattern images + white + black; order as documented: {order_ok}")
    gp = make_graycode(width, height)
    crop = np.ascontiguousarray(got[:, :100, :160])       # a 160x100 "camera" that sees the projector 1:1
    res = run_getprojpixel(crop, gp, got.shape[0] - 2, 40, max_pixels=None, seed=0)
    v, u = np.mgrid[0:100, 0:160]
    gpp_ok = np.array_equal(res["proj_col"], u) and np.array_equal(res["proj_row"], v)
    print(f"getprojpixel: returns (error, (x=column, y=row)); identity on the patterns themselves: {gpp_ok}")
    res = run_decode_stereo(crop, gp, got.shape[0] - 2, repeat=1)
    print(f"decode-stereo: works with two identical cameras, disparity {res['disparity_shape']}, "
          f"{res['n_disparity_nonzero']} non-zero (expected 0)")
    return 0 if order_ok and gpp_ok else 1


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("stack", nargs="?", help="(n, H, W) uint8 .npy in OpenCV's order")
    ap.add_argument("out", nargs="?", help="output .npz")
    ap.add_argument("--mode", choices=MODES, default="getprojpixel")
    ap.add_argument("--projector", default="1280x800", help="projector WxH the stack was made for")
    ap.add_argument("--max-pixels", type=int, default=None,
                    help="getprojpixel: decode a random subset of N pixels and extrapolate the time")
    ap.add_argument("--repeat", type=int, default=1, help="decode-stereo: runs (median reported)")
    ap.add_argument("--white-threshold", type=int, default=None, help="setWhiteThreshold (OpenCV default 5)")
    ap.add_argument("--black-threshold", type=int, default=40,
                    help="setBlackThreshold (OpenCV default 40); also used for the getprojpixel shadow mask")
    ap.add_argument("--seed", type=int, default=0, help="seed of the --max-pixels subset")
    ap.add_argument("--generate-patterns", metavar="OUT.npy", help="write OpenCV's patterns + white + black")
    ap.add_argument("--check", action="store_true", help="verify the pattern order and both modes, then exit")
    args = ap.parse_args()
    try:
        width, height = (int(s) for s in args.projector.lower().split("x"))
    except ValueError:
        ap.error(f"--projector must look like 1280x800, found {args.projector!r}")

    if args.check:
        return check(width, height)
    if args.generate_patterns:
        pats = opencv_patterns(width, height)
        np.save(args.generate_patterns, pats)
        print(f"wrote {pats.shape[0]} OpenCV {cv2.__version__} pattern images {width}x{height} "
              f"to {args.generate_patterns}")
        return 0
    if not (args.stack and args.out):
        ap.error("STACK.npy and OUT.npz are needed (or --generate-patterns / --check)")

    stack = np.load(args.stack, mmap_mode=None)
    gp = make_graycode(width, height, white_threshold=args.white_threshold, black_threshold=args.black_threshold)
    n_patterns = gp.getNumberOfPatternImages()
    if stack.dtype != np.uint8 or stack.ndim != 3 or stack.shape[0] != n_patterns + 2:
        sys.exit(f"{args.stack}: expected ({n_patterns + 2}, H, W) uint8 (patterns, white, black) for a "
                 f"{width}x{height} projector, found {stack.shape} {stack.dtype}")
    if args.mode == "getprojpixel":
        res = run_getprojpixel(stack, gp, n_patterns, args.black_threshold,
                               max_pixels=args.max_pixels, seed=args.seed)
    else:
        res = run_decode_stereo(stack, gp, n_patterns, repeat=max(1, args.repeat))
    H, W = stack.shape[1:]
    meta = {"mode": args.mode, "opencv_version": cv2.__version__, "width": W, "height": H,
            "white_threshold": args.white_threshold if args.white_threshold is not None else 5,
            "black_threshold": args.black_threshold}
    np.savez(args.out, **res, **{k: np.array(v) for k, v in meta.items()})
    summary = {**meta, **{k: (float(v) if isinstance(v, float) else v) for k, v in res.items()
                          if not isinstance(v, np.ndarray)}}
    print(json.dumps(summary))
    return 0


if __name__ == "__main__":
    sys.exit(main())
