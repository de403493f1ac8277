"""Camera + projector bundle adjustment vs OpenCV's stereoCalibrate on the same corners.

Input: the simulator's true rig, 20 board poses from ``board_poses`` (10 x 7 board, 54 corners), corners
projected exactly into the camera and the projector plus Gaussian noise (0.03 px camera, 0.02 px
projector: what the simulated detection and corner fit give). Both solvers start from the same
per-device calibrations (``calibrate_device``) and refine both devices' intrinsics (k3 fixed), their
relative pose and the board poses. Prints time (median of 5) and the deviation from the truth.

Run: .venv/bin/python benchmarks/calib/bench_calibration.py [--markdown]

``--markdown`` prints the table and the ratio sentence of docs/benchmarks.md (a ``make docs-figures`` block).
"""

from __future__ import annotations

import argparse
import time
import warnings

import cv2
import numpy as np

from rangekit.boards import Board
from rangekit.calib.camera import Correspondences, calibrate_device
from rangekit.calib.projector import bundle_adjust, initial_T_proj_cam
from rangekit.geometry import apply_T, make_T, rotation_angle
from rangekit.sim.writers.calibration import board_poses
from rangekit.sim.devices.sim_rig import default_rig


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--markdown", action="store_true", help="print the table of docs/benchmarks.md")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    truth = default_rig()
    cam, proj = truth.camera, truth.projector
    board = Board()
    obj = board.object_points()
    rng = np.random.default_rng(0)
    poses = board_poses(truth, board, 20, seed=0)
    ids = np.arange(len(obj))
    cam_uv = [cam.project(apply_T(T, obj)) + rng.normal(0, 0.03, (len(obj), 2)) for T in poses]
    proj_uv = [proj.project(apply_T(T, obj)) + rng.normal(0, 0.02, (len(obj), 2)) for T in poses]
    cc = calibrate_device([Correspondences(ids, u) for u in cam_uv], obj, cam.size, name="camera")
    pc = calibrate_device([Correspondences(ids, u) for u in proj_uv], obj, proj.size, name="projector")
    T0 = initial_T_proj_cam(cc.T_dev_board, pc.T_dev_board)
    T_cam_proj_true = cam.T_cam_world @ proj.T_world_cam
    T_proj_cam_true = np.linalg.inv(T_cam_proj_true)

    def ours():
        return bundle_adjust(cc.device, pc.device, T0, cc.T_dev_board, obj,
                             {i: (ids, u) for i, u in enumerate(cam_uv)}, {i: (ids, u) for i, u in enumerate(proj_uv)},
                             sigma_camera=0.03, sigma_projector=0.02)

    def opencv():
        o = [obj.astype(np.float32)] * len(poses)
        flags = cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_K3
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
        return cv2.stereoCalibrate(o, [u.astype(np.float32) for u in cam_uv], [u.astype(np.float32) for u in proj_uv],
                                   cc.device.K.copy(), cc.device.dist.copy(), pc.device.K.copy(),
                                   pc.device.dist.copy(), cam.size, flags=flags, criteria=crit)

    def timed(fn):
        ts, out = [], None
        for _ in range(5):
            t = time.perf_counter()
            out = fn()
            ts.append(time.perf_counter() - t)
        return float(np.median(ts)), out

    t_ours, res = timed(ours)
    t_cv, cv_out = timed(opencv)
    T_ours = np.linalg.inv(res.T_cam_proj)
    T_cv = make_T(cv_out[5], cv_out[6].ravel())

    def report(name, t, T_proj_cam, Kc, Kp):
        rot = np.degrees(rotation_angle(T_proj_cam[:3, :3] @ T_proj_cam_true[:3, :3].T))
        base = (np.linalg.norm(T_proj_cam[:3, 3]) / np.linalg.norm(T_proj_cam_true[:3, 3]) - 1) * 100
        pp = np.hypot(*(Kp[:2, 2] - proj.K[:2, 2]))
        fx = (Kp[0, 0] / proj.K[0, 0] - 1) * 100
        print(f"| {name} | {t * 1e3:.0f} ms | {rot:.4f} deg | {base:+.4f}% | {fx:+.4f}% | {pp:.3f} px |")

    names = (("rangekit `bundle_adjust` (LM, Jacobian by grouped finite differences)",
              "OpenCV `stereoCalibrate` (CALIB_USE_INTRINSIC_GUESS, FIX_K3)") if args.markdown
             else ("rangekit bundle_adjust", "OpenCV stereoCalibrate"))
    print("| solver | time | rotation error | baseline error | projector fx error | projector principal point error |")
    print("|---|---|---|---|---|---|")
    report(names[0], t_ours, T_ours, res.camera.K, res.projector.K)
    report(names[1], t_cv, T_cv, cv_out[1], cv_out[3])
    if args.markdown:
        faster = f"rangekit is {t_cv / t_ours:.1f}x" if t_ours <= t_cv else f"OpenCV is {t_ours / t_cv:.1f}x"
        print(f"\n{faster} faster (median of 5 calls each).")
    else:
        print(f"speed ratio (OpenCV / rangekit): {t_cv / t_ours:.2f}")


if __name__ == "__main__":
    main()
