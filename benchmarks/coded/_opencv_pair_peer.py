"""OpenCV contrib's two-camera Gray-code pipeline, as its structured-light sample ``pointcloud.cpp`` runs it: the
peer of ``pair_vs_opencv.py``. Runs inside .venv-bench (``benchmarks/coded/setup_opencv_contrib.sh``): only numpy
and cv2 (opencv-contrib-python-headless) are imported.

    .venv-bench/bin/python benchmarks/coded/_opencv_pair_peer.py CAM1.npy CAM2.npy CALIB.npz OUT.npz --projector WxH

``CAM1.npy``, ``CAM2.npy``: (n, H, W) uint8 stacks in OpenCV's order (patterns, then white, then black), each of
the camera the calibration names. ``CALIB.npz``: ``K1, D1, K2, D2`` and ``R, T`` with ``x2 = R x1 + T`` (OpenCV's
``stereoCalibrate`` convention, metres). The sample's steps: ``stereoRectify`` (alpha -1), every image remapped
(nearest), ``GrayCodePattern.decode`` to a disparity map, ``reprojectImageTo3D`` with ``Q``; the points where the
disparity is set, turned back into camera 1's unrectified frame (``R1^T``). OUT.npz: ``points`` (m, 3) in camera
1's frame, ``points_otsu`` those the sample's Otsu mask of the scaled disparity keeps, ``seconds``.
"""

from __future__ import annotations

import argparse
import sys
import time

import cv2
import numpy as np


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("cam1")
    ap.add_argument("cam2")
    ap.add_argument("calib")
    ap.add_argument("out")
    ap.add_argument("--projector", required=True, help="WxH the patterns were made for")
    args = ap.parse_args()
    width, height = (int(s) for s in args.projector.lower().split("x"))
    stacks = [np.load(args.cam1), np.load(args.cam2)]
    c = np.load(args.calib)
    gp = cv2.structured_light.GrayCodePattern.create(width, height)
    n = gp.getNumberOfPatternImages()
    for s, name in zip(stacks, (args.cam1, args.cam2)):
        if s.dtype != np.uint8 or s.ndim != 3 or s.shape[0] != n + 2:
            sys.exit(f"{name}: expected ({n + 2}, H, W) uint8, found {s.shape} {s.dtype}")
    size = (stacks[0].shape[2], stacks[0].shape[1])
    t0 = time.perf_counter()
    R1, R2, P1, P2, Q, _, _ = cv2.stereoRectify(c["K1"], c["D1"], c["K2"], c["D2"], size, c["R"], c["T"].reshape(3, 1),
                                                flags=0, alpha=-1, newImageSize=size)
    maps = [cv2.initUndistortRectifyMap(c["K1"], c["D1"], R1, P1, size, cv2.CV_32FC1),
            cv2.initUndistortRectifyMap(c["K2"], c["D2"], R2, P2, size, cv2.CV_32FC1)]
    rect = [[cv2.remap(im, mx, my, cv2.INTER_NEAREST, borderMode=cv2.BORDER_CONSTANT, borderValue=0) for im in s]
            for s, (mx, my) in zip(stacks, maps)]
    patterns = [r[:n] for r in rect]
    whites, blacks = [r[n] for r in rect], [r[n + 1] for r in rect]
    ok, disparity = gp.decode(patterns, None, blacks, whites, cv2.structured_light.DECODE_3D_UNDERWORLD)
    if not ok:
        sys.exit("GrayCodePattern.decode() returned False")
    disparity = disparity.astype(np.float32)               # the sample: disparityMap.convertTo(CV_32FC1)
    cloud = cv2.reprojectImageTo3D(disparity, Q, handleMissingValues=True, ddepth=-1)
    scaled = cv2.normalize(disparity, None, 0, 255, cv2.NORM_MINMAX, cv2.CV_8U)
    _, otsu = cv2.threshold(scaled, 0, 255, cv2.THRESH_OTSU + cv2.THRESH_BINARY)
    seconds = time.perf_counter() - t0
    valid = (disparity != 0) & np.all(np.isfinite(cloud), axis=2) & (cloud[..., 2] < 1000)
    # points in the rectified camera 1's frame back to camera 1's frame: X_cam1 = R1^T X_rect1
    points = cloud[valid].astype(np.float64) @ R1
    keep = (otsu > 0)[valid]
    np.savez(args.out, points=points, points_otsu=points[keep], seconds=seconds)
    print(f"opencv {cv2.__version__}: {len(points)} points ({int(keep.sum())} in the Otsu mask) in {seconds:.2f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
