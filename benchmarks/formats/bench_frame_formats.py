"""A session's frame formats side by side (issue 36): one view's frames written and read as PNG (OpenCV's fastest
level, as rangekit writes them) and as ``.npy.zst`` (rangekit.npy_zst), on one thread, with the bytes on disk.

    .venv/bin/python benchmarks/formats/bench_frame_formats.py SESSION [VIEW]

SESSION: a session folder (``rangekit scan --out S --no-process``, either format); VIEW: its view index (0).
Prints JSON: milliseconds per frame to encode and to decode (medians of 3 passes over the view's frames), the
bytes, and the ratios; each decoded frame is checked equal to the original.
"""

from __future__ import annotations

import json
import statistics
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from rangekit.formats.capture import list_images
from rangekit.io import decode_image, encode_png, read_png
from rangekit.npy_zst import encode_npy_zst


def _timed(fn, items) -> tuple[float, list]:
    times, out = [], None
    for _ in range(3):
        t = time.perf_counter()
        out = [fn(x) for x in items]
        times.append(time.perf_counter() - t)
    return statistics.median(times) / len(items) * 1e3, out


def main(session: str, view: int = 0) -> dict:
    cv2.setNumThreads(1)
    images = [read_png(p) for p in list_images(Path(session) / f"view_{view:03d}")]
    result = {"frames": len(images), "shape": list(images[0].shape), "dtype": str(images[0].dtype)}
    for name, encode in (("png", lambda im: encode_png(im)), ("npy.zst", lambda im: encode_npy_zst(im))):
        enc_ms, blobs = _timed(encode, images)
        dec_ms, back = _timed(lambda b: decode_image(b, name), blobs)
        assert all(np.array_equal(a, b) for a, b in zip(images, back)), name
        result[name] = {"encode_ms": round(enc_ms, 2), "decode_ms": round(dec_ms, 2),
                        "bytes": sum(len(b) for b in blobs)}
    result["npy.zst / png"] = {k: round(result["npy.zst"][k] / result["png"][k], 3)
                               for k in ("encode_ms", "decode_ms", "bytes")}
    return result


if __name__ == "__main__":
    print(json.dumps(main(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 0), indent=1))
