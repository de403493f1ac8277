"""Issue 47's simulator acceptance: a two-camera Gray-code capture whose files are named for the other camera and
whose calibration is a few pixels off, reconstructed by ``rangekit reconstruct`` as a user would run it, beside
OpenCV's own pipeline (``pointcloud.cpp``: rectify, ``GrayCodePattern.decode``, reproject) given the true
calibration and the files the right way round.

    .venv/bin/python benchmarks/coded/pair_vs_opencv.py [--off-deg 0.5] [--keep DIR] [--markdown]

Needs .venv-bench for OpenCV's side (``bash benchmarks/coded/setup_opencv_contrib.sh``); without it, rangekit's
side alone is measured. Both clouds are measured the same way against the simulator's true surface: distance of
every point to the scene's mesh (RMS, median, 99th percentile, mm), points, the share within 0.5 mm, and roughness
(the median RMS of local planes, 2 mm radius).
Conditions: the default rig's camera at 640x512, a second camera turned 25 degrees about the turntable axis, a
1100x688 projector (never given to either), the lumpy default object; the rig file's camera 2 turned
``--off-deg`` about a tilted axis (0.5 deg: about 7 px of epipolar distance).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

ROOT = Path(__file__).resolve().parents[2]
PEER = Path(__file__).with_name("_opencv_pair_peer.py")
PROJECTOR = (1100, 688)
PRESET = "opencv:graycode"
ROUGHNESS_RADIUS_M = 0.002


def bench_python() -> Path | None:
    for venv in (ROOT / ".venv-bench",):
        if (venv / "bin" / "python").exists():
            return venv / "bin" / "python"
    return None


def make_capture(folder: Path, off_deg: float):
    """(true rig, the rig file a few pixels off, world mesh): the crossed capture written into ``folder``."""
    from rangekit.geometry import axis_angle_to_R, make_T
    from rangekit.rig.rig_file import Rig, save_rig
    from rangekit.sim import default_rig, default_scene
    from rangekit.sim.writers.tool_pair import write_tool_pair

    r = default_rig()
    cam1 = r.camera.resized(640, 512)
    cam2 = replace(cam1.with_pose(make_T(axis_angle_to_R([0, 0, 1], np.radians(-25)), [0, 0, 0]) @ cam1.T_world_cam),
                   name="cam2")
    scene = default_scene()
    write_tool_pair(folder, PRESET, replace(r, projector=r.projector.resized(*PROJECTOR)), (cam1, cam2), scene=scene,
                    crossed=True)
    true = Rig(cameras=(cam1, cam2), projector=None)
    turned = cam2.with_pose(cam2.T_world_cam @ make_T(axis_angle_to_R([1, 0.3, 0], np.radians(off_deg)), [0, 0, 0]))
    off = Rig(cameras=(cam1, turned), projector=None)
    save_rig(true, folder / "rig_true.json")
    save_rig(off, folder / "rig_off.json")
    return true, off, scene.world_mesh()


def errors_mm(points: np.ndarray, mesh) -> np.ndarray:
    from rangekit.surface.raycast import mesh_scene, query_scene

    scene, c = mesh_scene(mesh)
    closest = query_scene(scene, "compute_closest_points", (points - c).astype(np.float32))["points"]
    return np.linalg.norm(points - c - closest.astype(np.float64), axis=1) * 1e3


def figures(name: str, points: np.ndarray, mesh) -> dict:
    """Points, their distances to the true surface, and roughness: the median RMS of the plane through each 20th
    point's neighbours within 2 mm (rangekit.metrology.cloud_compare.roughness), mm."""
    from rangekit.metrology.cloud_compare import roughness

    d = errors_mm(points, mesh)
    rough = roughness(points, points[::20], ROUGHNESS_RADIUS_M)
    return {"name": name, "points": int(len(points)), "roughness_mm": float(np.nanmedian(rough) * 1e3),
            "rms_mm": float(np.sqrt(np.mean(d ** 2))),
            "median_mm": float(np.median(d)), "p99_mm": float(np.percentile(d, 99)),
            "within_0.5mm": float(np.mean(d <= 0.5))}


def opencv_side(folder: Path, true_rig, mesh, work: Path, log=print) -> list[dict]:
    py = bench_python()
    if py is None:
        log("OpenCV's side skipped: no .venv-bench (bash benchmarks/coded/setup_opencv_contrib.sh)")
        return []
    from rangekit.geometry import invert_T

    cam1, cam2 = true_rig.cameras
    n = len(list(folder.glob("pattern_cam1_im*.png")))
    for k, number in ((1, 2), (2, 1)):            # the files are crossed: camera 1's frames are named cam2
        stack = np.stack([cv2.imread(str(folder / f"pattern_cam{number}_im{i}.png"), cv2.IMREAD_GRAYSCALE)
                          for i in range(1, n + 1)])
        np.save(work / f"cam{k}.npy", stack)
    T_cam2_cam1 = invert_T(cam2.T_world_cam) @ cam1.T_world_cam
    np.savez(work / "calib.npz", K1=cam1.K, D1=np.asarray(cam1.dist, float), K2=cam2.K,
             D2=np.asarray(cam2.dist, float), R=T_cam2_cam1[:3, :3], T=T_cam2_cam1[:3, 3])
    run = subprocess.run([str(py), str(PEER), str(work / "cam1.npy"), str(work / "cam2.npy"), str(work / "calib.npz"),
                          str(work / "opencv.npz"), "--projector", f"{PROJECTOR[0]}x{PROJECTOR[1]}"],
                         capture_output=True, text=True, check=True)
    log(run.stdout.strip())
    with np.load(work / "opencv.npz") as res:
        to_world = lambda p: p @ cam1.T_world_cam[:3, :3].T + cam1.T_world_cam[:3, 3]
        return [figures("OpenCV pointcloud.cpp (true rig, right names)", to_world(res["points"]), mesh),
                figures("  its Otsu mask", to_world(res["points_otsu"]), mesh)]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--off-deg", type=float, default=0.5, help="camera 2 of the rig file turned by this (degrees)")
    ap.add_argument("--keep", type=Path, help="write the capture and clouds here (default: a temporary folder)")
    ap.add_argument("--markdown", action="store_true", help="only the table on standard output (the rest on stderr)")
    args = ap.parse_args()
    log = (lambda *a, **kw: print(*a, **kw, file=sys.stderr)) if args.markdown else print
    with tempfile.TemporaryDirectory() as tmp:
        work = args.keep or Path(tmp)
        folder = work / "capture"
        true_rig, _, mesh = make_capture(folder, args.off_deg)
        out = work / "rangekit.ply"
        run = subprocess.run([sys.executable, "-m", "rangekit", "reconstruct", str(folder), "--pattern", PRESET,
                              "--rig", str(folder / "rig_off.json"), "--projector", f"{PROJECTOR[0]}x{PROJECTOR[1]}",
                              "--out", str(out), "--force"], capture_output=True, text=True)
        log(run.stdout.strip(), run.stderr.strip(), sep="\n")
        rows = []
        if run.returncode == 0:
            from rangekit.formats.clouds import load_cloud

            rows.append(figures("rangekit reconstruct (rig off, names crossed)", np.asarray(load_cloud(out).points),
                                mesh))
        rows += opencv_side(folder, true_rig, mesh, work, log)
        print(("" if args.markdown else "\n") + "| cloud | points | roughness mm | to the truth: RMS mm | median mm | p99 mm | within 0.5 mm |\n"
              "|---|---|---|---|---|---|---|")
        for r in rows:
            print(f"| {r['name']} | {r['points']} | {r['roughness_mm']:.3f} | {r['rms_mm']:.3f} | {r['median_mm']:.3f} | "
                  f"{r['p99_mm']:.3f} | {100 * r['within_0.5mm']:.1f}% |")
        if not args.markdown:
            print(json.dumps(rows))
    return 0 if run.returncode == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
