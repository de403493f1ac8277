"""Depth from a ToF capture folder or a stereo pair, compared with ``ground_truth.npz`` when the folder
has one, written as depth outputs: the work behind ``rangekit tof`` and ``rangekit stereo``.

Outputs (:func:`write_depth_outputs`): ``depth.npy`` (float64 camera z in metres, NaN where invalid),
``depth.png`` (turbo colour map, white where invalid), ``confidence.npy`` (float32 in [0, 1]) and
``confidence.png`` when given, ``range.npy`` when given, and ``cloud.ply`` (valid points, world frame).

Each function reports what it found through ``progress(msg)`` (one line per fact, as the command
prints them) and returns the depth outputs it wrote.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from rangekit.errors import ConfigError, InputError, naming
from rangekit.formats.range_files import load_ground_truth, load_tof_folder
from rangekit.image_header import check_image_files
from rangekit.io import atomic_save_npy, read_png, write_png
from rangekit.progress import call_progress
from rangekit.rig.plausibility import check_stereo_baseline
from rangekit.rig.rig_file import load_rig
from rangekit.formats.sessions.files import CLOUD_FILE, RIG_FILE

__all__ = ["DepthRun", "tof_depth_files", "stereo_depth_files", "write_depth_outputs"]


@dataclass(frozen=True, eq=False)
class DepthRun:
    """The files written into ``out`` and the number of points in its ``cloud.ply``."""

    out: Path
    names: list[str]
    n_points: int


def tof_depth_files(raw_dir: str | Path, out: str | Path, *, min_snr: float = 3.0,
                    flying_angle: float | None = math.radians(15.0), max_range: float | None = None,
                    min_fill: float | None = 0.5, progress: Callable | None = None) -> DepthRun:
    """Range, depth, confidence and a cloud from a ToF capture folder (pulsed or continuous wave).

    ``flying_angle`` (radians) None keeps flying pixels, ``min_fill`` None partially covered ones
    (:func:`rangekit.tof.partial_pixels`); ``max_range`` metres (None: the plan's unambiguous
    range). Against ``ground_truth.npz``: range RMS without wrong wraps (errors above 0.3 m).
    """
    from rangekit.tof import decode_cw, pulsed_range, range_to_depth, range_to_points

    raw = load_tof_folder(raw_dir)
    cam = raw.camera
    if raw.pulsed:
        rng_map = pulsed_range(raw.round_trip_s)
        depth = range_to_depth(rng_map, cam)
        valid = np.isfinite(rng_map)
        points = range_to_points(rng_map, cam)[valid]
        confidence = valid.astype(np.float32)
        call_progress(progress, f"pulsed: {valid.mean():.1%} of {cam.width}x{cam.height} pixels returned")
    else:
        res = decode_cw(raw.samples, raw.plan, cam, electrons_per_unit=raw.electrons_per_dn,
                        read_noise_e=raw.read_noise_e, saturation=raw.saturation_dn, min_snr=min_snr,
                        flying_angle=flying_angle, max_range=max_range, min_fill=min_fill)
        rng_map, depth, points, confidence, valid = res.range, res.depth, res.points, res.confidence, res.valid
        n = valid.size
        call_progress(progress, f"{raw.plan.describe()} ({raw.plan.unambiguous_range:.3f} m unambiguous): valid "
                                f"{valid.sum() / n:.1%}, low signal {res.low_signal.sum() / n:.1%}, ambiguous "
                                f"{res.ambiguous.sum() / n:.1%}, flying {res.flying.sum() / n:.1%}, partial "
                                f"{res.partial.sum() / n:.1%}")
    truth = load_ground_truth(raw_dir, shape=rng_map.shape)
    if truth is not None and "range" in truth:
        ok = valid & np.isfinite(truth["range"]) & truth.get("valid", np.ones_like(valid))
        if ok.any():
            err = (rng_map - truth["range"])[ok]
            wrong = np.abs(err) > 0.3
            call_progress(progress, f"against ground_truth.npz ({ok.sum():,} pixels): range RMS "
                                    f"{np.sqrt(np.mean(err[~wrong] ** 2)) * 1e3:.2f} mm, median |error| "
                                    f"{np.median(np.abs(err)) * 1e3:.2f} mm, wrong wrap (> 0.3 m) {wrong.mean():.3%}")
    names = write_depth_outputs(out, depth, points, range_map=rng_map, confidence=confidence)
    return DepthRun(Path(out), names, len(points))


def stereo_depth_files(left: str | Path, right: str | Path, rig_file: str | Path, out: str | Path, *,
                       method: str = "census-sgm", min_depth: float = 0.4, alpha: float = 0.0,
                       num_disparities: int | None = None, progress: Callable | None = None) -> DepthRun:
    """Depth of the left camera from a raw stereo pair and a rig file with two cameras (left first).

    Against ``ground_truth.npz`` in the left image's folder (same size): coverage of the visible pixels,
    depth RMS and median error.
    """
    import time

    from rangekit.stereo import stereo_depth

    t0 = time.perf_counter()
    rig = load_rig(rig_file)
    if len(rig.cameras) < 2:
        raise ConfigError(f"{rig_file}: the stereo command needs two cameras in 'cameras' (left = cameras[0], "
                          f"right = cameras[1]), found {len(rig.cameras)}")
    check_stereo_baseline(rig, str(rig_file))  # a rig file in millimetres: depths 1000 times off
    check_image_files([left, right], what="stereo pair", same_size=False)  # the budget, before any pixel
    left_img, right_img = read_png(left), read_png(right)
    if left_img.shape[:2] != right_img.shape[:2]:
        raise InputError(f"{left} is {left_img.shape[1]}x{left_img.shape[0]} but {right} is "
                         f"{right_img.shape[1]}x{right_img.shape[0]} (width x height); a stereo pair needs two "
                         "images of one size")
    left_cam = rig.cameras[0]
    if left_img.shape[:2] != (left_cam.height, left_cam.width):
        raise InputError(f"{left} is {left_img.shape[1]}x{left_img.shape[0]} but the left camera {left_cam.name!r} "
                         f"in {rig_file} is {left_cam.width}x{left_cam.height} (width x height); use the images this "
                         "rig recorded, or a rig calibrated at this resolution")
    opts = {} if num_disparities is None else {"num_disparities": num_disparities}
    with naming(rig_file):  # rectification refuses a rig without a usable baseline
        res = stereo_depth(left_img, right_img, rig.cameras[0], rig.cameras[1], method=method, min_depth=min_depth,
                           alpha=alpha, **opts)
    dmap = res.disparity
    ok = np.isfinite(res.depth)
    call_progress(progress, f"{dmap.method}: disparities [{dmap.min_disparity}, "
                            f"{dmap.min_disparity + dmap.num_disparities}) px, baseline "
                            f"{res.rectification.baseline * 1e3:.1f} mm; depth for {ok.mean():.1%} of the left "
                            f"image in {time.perf_counter() - t0:.1f} s")
    report_depth_truth(Path(left).parent, res.depth, progress)
    names = write_depth_outputs(out, res.depth, res.points, confidence=res.confidence)
    return DepthRun(Path(out), names, len(res.points))


def report_depth_truth(folder: Path, depth: np.ndarray, progress: Callable | None) -> None:
    """Say how ``depth`` ((H, W) camera z, metres) compares with the simulator's ``ground_truth.npz`` in ``folder``
    (when there is one of that size): coverage of its visible pixels, RMS and median error."""
    truth = load_ground_truth(folder)
    if truth is None or "depth" not in truth or truth["depth"].shape != depth.shape:
        return
    vis = truth.get("valid", np.isfinite(truth["depth"])) & np.isfinite(truth["depth"])
    both = vis & np.isfinite(depth)
    if both.any():
        err = (depth - truth["depth"])[both]
        call_progress(progress, f"against ground_truth.npz: depth for {both.sum() / max(vis.sum(), 1):.1%} of "
                                f"the {vis.sum():,} visible pixels, RMS {np.sqrt(np.mean(err ** 2)) * 1e3:.2f} "
                                f"mm, median |error| {np.median(np.abs(err)) * 1e3:.2f} mm")


def dots_depth_folder(folder: str | Path, *, rig_file: str | Path | None = None, progress: Callable | None = None):
    """Depth of a dot sensor's camera from its capture folder (:mod:`rangekit.formats.dots_capture`,
    :func:`rangekit.stereo.dots.dots_depth`); ``rig_file`` replaces the folder's rig.json. Says its coverage and,
    on a simulated capture, its errors against the truth. Returns the :class:`rangekit.stereo.StereoResult`."""
    import time

    from rangekit.formats.dots_capture import load_dots_capture
    from rangekit.stereo.dots import dots_depth

    t0 = time.perf_counter()
    folder = Path(folder)
    cap = load_dots_capture(folder, load_rig(rig_file) if rig_file else None)
    with naming(rig_file or folder / RIG_FILE):  # rectification refuses a rig without a usable baseline
        res = dots_depth(cap.image, cap.reference, cap.rig.cameras[0], cap.rig.projector, cap.reference_distance,
                         where=str(folder / "reference.png"))
    dmap = res.disparity
    call_progress(progress, f"dots against the reference at {cap.reference_distance:.3f} m: baseline "
                            f"{res.rectification.baseline * 1e3:.1f} mm, disparities [{dmap.min_disparity}, "
                            f"{dmap.min_disparity + dmap.num_disparities}) px; depth for "
                            f"{np.isfinite(res.depth).mean():.1%} of the image in {time.perf_counter() - t0:.1f} s")
    report_depth_truth(folder, res.depth, progress)
    return res


def write_depth_outputs(out: str | Path, depth: np.ndarray, points: np.ndarray, *,
                        range_map: np.ndarray | None = None, confidence: np.ndarray | None = None) -> list[str]:
    """Write depth.npy/png, optional range.npy and confidence.npy/png, and cloud.ply; returns file names."""
    from rangekit.colour import colourise
    from rangekit.formats.clouds import save_cloud
    from rangekit.surface.cloud import PointCloud

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    names = ["depth.npy", "depth.png"]
    atomic_save_npy(out / "depth.npy", np.asarray(depth, dtype=np.float64))
    ok = np.isfinite(depth)
    lo, hi = (np.percentile(depth[ok], [1, 99]) if ok.any() else (0.0, 1.0))
    write_png(out / "depth.png", colourise(depth, float(lo), float(max(hi, lo))))
    if range_map is not None:
        atomic_save_npy(out / "range.npy", np.asarray(range_map, dtype=np.float64))
        names.append("range.npy")
    if confidence is not None:
        atomic_save_npy(out / "confidence.npy", np.asarray(confidence, dtype=np.float32))
        write_png(out / "confidence.png", np.rint(np.clip(confidence, 0, 1) * 255).astype(np.uint8))
        names += ["confidence.npy", "confidence.png"]
    save_cloud(out / CLOUD_FILE, PointCloud(np.asarray(points, dtype=np.float64).reshape(-1, 3)))
    names.append(CLOUD_FILE)
    return names
