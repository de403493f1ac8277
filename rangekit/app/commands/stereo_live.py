"""``rangekit stereo --device``: capture a synchronised pair from an attached OAK-D with the dot projector on
(:func:`rangekit.drivers.depthai.stereo.capture_stereo_pair`), run the same matcher as ``rangekit stereo`` on
files (:func:`rangekit.stereo.stereo_depth`) and write the same depth outputs, plus the pair itself
(``left.png``, ``right.png``) and the device's calibration (``rig.json``), so the run can be repeated
offline with ``rangekit stereo OUT/left.png OUT/right.png --rig OUT/rig.json``.

With ``on_device`` the camera's own StereoDepth (aligned to the left camera) is saved next to ours as
``device_depth.npy`` / ``device_depth.png`` and the difference is summarised (:func:`compare_depths`).

``rangekit stereo --device --camera realsense``: a RealSense matches its pair on board (emitter on,
:func:`rangekit.drivers.realsense.depth.capture_range`); :func:`realsense_depth_device` writes its depth frame as the
same depth outputs, with the range map (``range.npy``) and the depth stream's intrinsics as the SDK reports them
(``rig.json``: that camera, its ``devices.camera`` section), live or from a recording.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from rangekit.app.commands.ranges import write_depth_outputs
from rangekit.errors import naming
from rangekit.io import atomic_save_npy, write_png
from rangekit.progress import call_progress
from rangekit.rig.rig_file import Rig, save_rig
from rangekit.formats.sessions.files import RIG_FILE

__all__ = ["DepthComparison", "LiveStereoRun", "compare_depths", "stereo_depth_device", "realsense_depth_device"]


@dataclass(frozen=True)
class DepthComparison:
    """Ours against the device's depth on the left camera's pixels: the fraction of pixels each has,
    the pixels both have, and over those the median and RMS of (ours - device) and the median |difference|,
    metres."""

    ours_fraction: float
    device_fraction: float
    n_both: int
    median_m: float
    rms_m: float
    median_abs_m: float

    def line(self) -> str:
        return (f"ours vs the device's StereoDepth: depth for {self.ours_fraction:.1%} / {self.device_fraction:.1%} "
                f"of the pixels, {self.n_both:,} in both; difference (ours - device) median "
                f"{self.median_m * 1e3:+.2f} mm, RMS {self.rms_m * 1e3:.2f} mm, median |diff| "
                f"{self.median_abs_m * 1e3:.2f} mm")


@dataclass(frozen=True, eq=False)
class LiveStereoRun:
    out: Path
    names: list[str]
    n_points: int
    depth: np.ndarray                       # (H, W) ours, left camera z, metres, NaN invalid
    comparison: DepthComparison | None      # with on_device


def compare_depths(ours: np.ndarray, device: np.ndarray) -> DepthComparison:
    """Summary of two (H, W) depth maps in metres (NaN invalid) on one pixel grid."""
    a, b = np.isfinite(ours), np.isfinite(device)
    both = a & b
    d = (ours - device)[both]
    nan = float("nan")
    return DepthComparison(float(a.mean()), float(b.mean()), int(both.sum()),
                           float(np.median(d)) if d.size else nan, float(np.sqrt(np.mean(d ** 2))) if d.size else nan,
                           float(np.median(np.abs(d))) if d.size else nan)


def stereo_depth_device(out: str | Path, *, device_id: str | None = None, size: tuple[int, int] = (640, 400),
                        dots: float = 0.8, flood: float = 0.0, on_device: bool = False, method: str = "census-sgm",
                        min_depth: float = 0.4, alpha: float = 0.0, num_disparities: int | None = None,
                        search_timeout_s: float = 3.0, progress: Callable | None = None) -> LiveStereoRun:
    """Capture, match and write (module doc); ``progress(msg)`` gets one line per fact."""
    from rangekit.colour import colourise
    from rangekit.drivers.depthai.stereo import capture_stereo_pair
    from rangekit.stereo import stereo_depth

    t0 = time.perf_counter()
    pair = capture_stereo_pair(device_id, size=size, dots=dots, flood=flood, on_device=on_device,
                               search_timeout_s=search_timeout_s)
    emitters = ", ".join(f"{k} {'none on this model' if v is None else f'{v:g}'}"
                         for k, v in (("dot projector", pair.dots), ("flood", pair.flood)))
    call_progress(progress, f"depthai {pair.device_id}: frame {pair.sequence} from CAM_B/CAM_C at "
                            f"{pair.left.shape[1]}x{pair.left.shape[0]} ({emitters})")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_png(out / "left.png", pair.left)
    write_png(out / "right.png", pair.right)
    save_rig(Rig(cameras=(pair.left_camera, pair.right_camera),
                 devices={"depthai": {"device_id": pair.device_id, "sockets": ["CAM_B", "CAM_C"],
                                      "size": [pair.left.shape[1], pair.left.shape[0]]}}), out / RIG_FILE)
    opts = {} if num_disparities is None else {"num_disparities": num_disparities}
    with naming(f"depthai {pair.device_id} calibration"):
        res = stereo_depth(pair.left, pair.right, pair.left_camera, pair.right_camera, method=method,
                           min_depth=min_depth, alpha=alpha, **opts)
    ok = np.isfinite(res.depth)
    call_progress(progress, f"{res.disparity.method}: baseline {res.rectification.baseline * 1e3:.1f} mm; depth for "
                            f"{ok.mean():.1%} of the left image in {time.perf_counter() - t0:.1f} s")
    names = ["left.png", "right.png", RIG_FILE]
    names += write_depth_outputs(out, res.depth, res.points, confidence=res.confidence)
    comparison = None
    if pair.device_depth is not None:
        dev = pair.device_depth
        atomic_save_npy(out / "device_depth.npy", dev.astype(np.float64))
        both = np.concatenate([res.depth[ok], dev[np.isfinite(dev)]])
        lo, hi = np.percentile(both, [1, 99]) if both.size else (0.0, 1.0)
        write_png(out / "device_depth.png", colourise(dev, float(lo), float(max(hi, lo))))
        names += ["device_depth.npy", "device_depth.png"]
        if dev.shape == res.depth.shape:
            comparison = compare_depths(res.depth, dev)
            call_progress(progress, comparison.line())
        else:
            call_progress(progress, f"the device's depth is {dev.shape[1]}x{dev.shape[0]}, ours "
                                    f"{res.depth.shape[1]}x{res.depth.shape[0]}: not compared")
    return LiveStereoRun(out, names, len(res.points), res.depth, comparison)


def realsense_depth_device(out: str | Path, *, serial: str | None = None, bag: str | Path | None = None,
                           size: tuple[int, int] = (848, 480), fps: int = 30, laser_power: float | None = None,
                           search_timeout_s: float = 3.0, progress: Callable | None = None,
                           context=None) -> LiveStereoRun:
    """One RealSense depth frame written as depth outputs, ``range.npy`` and ``rig.json`` (module doc)."""
    from rangekit.drivers.realsense.depth import capture_range
    from rangekit.tof.range_maps import range_to_points

    frame = capture_range(serial, bag=bag, size=size, fps=fps, laser_power=laser_power,
                          search_timeout_s=search_timeout_s, context=context)
    ok = np.isfinite(frame.depth)
    emitter = "as recorded" if bag is not None else "on"
    call_progress(progress, f"RealSense {frame.serial}: depth frame {frame.frame_number} at {frame.camera.width}x"
                            f"{frame.camera.height} (emitter {emitter}, {frame.depth_units * 1e3:g} mm a unit); depth "
                            f"for {ok.mean():.1%} of the pixels")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    section = {"type": "realsense", "serial": frame.serial, "bag": None if bag is None else str(bag)}
    save_rig(Rig(cameras=(frame.camera,), devices={"camera": section}), out / RIG_FILE)
    points = range_to_points(frame.range, frame.camera)[ok]
    names = [RIG_FILE] + write_depth_outputs(out, frame.depth, points, range_map=frame.range)
    return LiveStereoRun(out, names, len(points), frame.depth, None)
