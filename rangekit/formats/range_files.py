"""Range-sensor folders on disk: reading a ToF capture and a simulated capture's ground truth.

A ToF capture folder (``rangekit sim render --sensor tof|tof-pulsed``, or a real sensor's dump in
the same layout) holds:

* ``tof.json``: ``kind`` ``rangekit.tof.cw/1`` with ``plan`` (``frequencies_hz``, ``steps_rad``),
  ``electrons_per_dn``, ``read_noise_e``, ``saturation_dn``; or ``rangekit.tof.pulsed/1``.
* ``rig.json``: the ToF camera as ``cameras[0]`` (a rig file, docs/rig.md).
* CW: ``samples/000.png ...``: 16-bit raw correlation samples, frequency-major (all phase steps of
  the first frequency, then the next). Pulsed: ``round_trip_s.npy`` (seconds, NaN where no return).
* optionally ``ground_truth.npz`` (range, depth, xyz, hit, valid) from the simulator.

A Kinect v2 depth map as RoomAlive Toolkit stores it (``cameraC/mean.bin``, ``variance.bin``; ``Calibrate.cs``
``CaptureDepthAndColor``: the mean and variance of 100 depth frames, float32 millimetres and mm^2, 0 where a pixel
had 50 valid samples or fewer) is read by :func:`read_kinect_depth` as a :class:`DepthMap`.

The depth outputs of ``rangekit tof`` and ``rangekit stereo`` are written by
:func:`rangekit.app.commands.ranges.write_depth_outputs`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.formats.capture import list_images, read_stack
from rangekit.errors import FileFormatError, InputError
from rangekit.image_header import check_image_files
from rangekit.io import read_json
from rangekit.rig.rig_file import load_rig
from rangekit.tof import FrequencyPlan, round_trip_problem
from rangekit.formats.sessions.files import RIG_FILE

__all__ = ["ToFFolder", "load_tof_folder", "load_ground_truth", "DepthMap", "read_kinect_depth", "KINECT_DEPTH_SIZE"]

#: A Kinect v2 depth image, width x height.
KINECT_DEPTH_SIZE = (512, 424)

TOF_KINDS = ("rangekit.tof.cw/1", "rangekit.tof.pulsed/1")


@dataclass(frozen=True, eq=False)
class ToFFolder:
    """A ToF capture read from disk. ``samples`` (K, H, W) uint16 for CW, ``round_trip_s`` (H, W) for pulsed."""

    folder: Path
    kind: str
    camera: PinholeCamera
    plan: FrequencyPlan | None
    samples: np.ndarray | None
    round_trip_s: np.ndarray | None
    electrons_per_dn: float
    read_noise_e: float
    saturation_dn: float | None

    @property
    def pulsed(self) -> bool:
        return self.kind == "rangekit.tof.pulsed/1"


def load_tof_folder(folder: str | Path) -> ToFFolder:
    """Read and check a ToF capture folder; errors name the file and what was expected."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileFormatError(f"{folder}: not a folder (expected a ToF capture folder with tof.json, {RIG_FILE} and "
                              "samples/)")
    meta = read_json(folder / "tof.json", what="ToF capture description")
    if not isinstance(meta, dict):
        raise FileFormatError(f"{folder / 'tof.json'}: expected a JSON object with 'kind', found a "
                              f"{type(meta).__name__}")
    kind = meta.get("kind")
    if kind not in TOF_KINDS:
        raise FileFormatError(f"{folder / 'tof.json'}: 'kind' must be one of {', '.join(TOF_KINDS)}, found {kind!r}")
    rig = load_rig(folder / RIG_FILE)
    cam = rig.camera
    if kind == "rangekit.tof.pulsed/1":
        path = folder / "round_trip_s.npy"
        _check_npy_shape(path, (cam.height, cam.width))
        try:
            dt = np.load(path)
        except (OSError, ValueError, EOFError) as exc:
            raise FileFormatError(f"{path}: cannot read the round-trip times ({str(exc)[:200]})") from None
        if dt.shape != (cam.height, cam.width):
            raise FileFormatError(f"{path}: shape {dt.shape} but the camera in {RIG_FILE} is {cam.width}x{cam.height}")
        problem = round_trip_problem(dt)
        if problem:
            raise FileFormatError(f"{path}: {problem}")
        return ToFFolder(folder, kind, cam, None, None, dt.astype(np.float64), 1.0, 0.0, None)
    try:
        plan = FrequencyPlan.from_dict(meta.get("plan"), where=f"{folder / 'tof.json'}: plan")
    except InputError as exc:
        raise FileFormatError(str(exc)) from None
    try:
        files = list_images(folder / "samples") if (folder / "samples").is_dir() else []
    except FileFormatError:
        files = []
    if len(files) != plan.n_samples:
        raise FileFormatError(f"{folder / 'samples'}: the frequency plan in tof.json ({plan.describe()}) needs "
                              f"{plan.n_samples} raw samples, found {len(files)}"
                              + (f" ({files[0].name} ... {files[-1].name})" if files else ""))
    headers = check_image_files(files, what="ToF raw samples")  # read_stack checks them again; cheap
    if headers and headers[0] is not None and (headers[0].width, headers[0].height) != (cam.width, cam.height):
        raise FileFormatError(f"{files[0]}: samples are {headers[0].width}x{headers[0].height} (width x height) "
                              f"but the camera in {RIG_FILE} is {cam.width}x{cam.height}")
    stack = read_stack(files, what="ToF raw samples")
    if stack.ndim != 3:
        raise FileFormatError(f"{folder / 'samples'}: expected single-channel (grey) raw samples, found images of "
                              f"shape {stack.shape[1:]} ({files[0].name})")
    if stack.shape[1:] != (cam.height, cam.width):
        raise FileFormatError(f"{folder / 'samples'}: samples are {stack.shape[2]}x{stack.shape[1]} but the "
                              f"camera in {RIG_FILE} is {cam.width}x{cam.height}")
    g = _number(meta, "electrons_per_dn", 1.0, folder / "tof.json", positive=True)
    rn = _number(meta, "read_noise_e", 0.0, folder / "tof.json")
    sat = _number(meta, "saturation_dn", None, folder / "tof.json", positive=True)
    return ToFFolder(folder, kind, cam, plan, stack, None, g, rn, sat)


def _number(meta: dict, key: str, default: float | None, path: Path, *, positive: bool = False) -> float | None:
    """``meta[key]`` as a finite float (> 0 if ``positive``, else >= 0), ``default`` when absent or null."""
    value = meta.get(key)
    if value is None:
        return default
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and np.isfinite(value) \
        and (value > 0 if positive else value >= 0)
    if not ok:
        raise FileFormatError(f"{path}: '{key}' must be a finite number {'> 0' if positive else '>= 0'}, found "
                              f"{json.dumps(value)[:200]}")
    return float(value)


@dataclass(frozen=True, eq=False)
class DepthMap:
    """A depth camera's map: ``depth`` (H, W) float64 camera-frame z in metres and ``sigma`` its per-pixel standard
    deviation in metres, NaN where invalid (both); ``valid`` where ``depth`` is finite."""

    depth: np.ndarray
    sigma: np.ndarray

    @property
    def valid(self) -> np.ndarray:
        return np.isfinite(self.depth)

    def points(self, camera: PinholeCamera) -> np.ndarray:
        """(H, W, 3) world points of ``camera`` (its pixel rays scaled to ``depth``), NaN where invalid."""
        from rangekit.camera import pixel_rays
        from rangekit.geometry import apply_T

        if camera.size != self.depth.shape[::-1]:
            raise InputError(f"DepthMap.points: the map is {self.depth.shape[1]}x{self.depth.shape[0]}, camera "
                             f"{camera.name!r} {camera.width}x{camera.height}")
        rays = pixel_rays(camera)
        p = (self.depth / rays[..., 2])[..., None] * rays
        return apply_T(camera.T_world_cam, p.reshape(-1, 3)).reshape(p.shape)


def read_kinect_depth(mean_path: str | Path, variance_path: str | Path | None = None, *,
                      mirror: bool = True) -> DepthMap:
    """RoomAlive's ``mean.bin`` (and ``variance.bin``): 512 x 424 little-endian float32, millimetres (mm^2), 0 =
    invalid, as a :class:`DepthMap` in metres, ``sigma = sqrt(variance)`` (a variance just below 0, float32
    cancellation in RoomAlive's running sums, reads 0; NaN without ``variance_path``). ``mirror``: flipped left to
    right (the Kinect's images are mirror images; the rig ``rangekit rig import`` makes of RoomAlive's ensemble
    describes them flipped, :mod:`rangekit.formats.rig_files.roomalive`). FileFormatError naming the file whose
    size is not 512 x 424 x 4 bytes or that holds values that are not finite or negative depths."""
    from rangekit.regular_files import read_regular_file

    W, H = KINECT_DEPTH_SIZE
    maps = []
    for path, what in ((mean_path, "depth"), (variance_path, "variance")):
        if path is None:
            maps.append(None)
            continue
        data = read_regular_file(path, what=f"a Kinect v2 {what} map", limit=W * H * 4 + 1)
        if len(data) != W * H * 4:
            raise FileFormatError(f"{path}: expected a {W}x{H} float32 {what} map ({W * H * 4} bytes), found "
                                  f"{len(data)} bytes")
        m = np.frombuffer(data, dtype="<f4").reshape(H, W).astype(np.float64)
        if not np.all(np.isfinite(m)) or (what == "depth" and np.any(m < 0)):
            raise FileFormatError(f"{path}: expected finite {what} values (millimetres, 0 = invalid), found "
                                  f"{np.count_nonzero(~np.isfinite(m) | (m < 0))} not finite or negative")
        maps.append(np.fliplr(m) if mirror else m)
    mean, variance = maps
    valid = mean > 0
    depth = np.where(valid, mean / 1000.0, np.nan)
    sigma = np.full_like(depth, np.nan) if variance is None else \
        np.where(valid, np.sqrt(np.maximum(variance, 0.0)) / 1000.0, np.nan)
    return DepthMap(depth, sigma)


_TRUTH_MAPS = {"range": "f", "depth": "f", "valid": "b", "hit": "b"}


def _check_npy_shape(path: Path, shape: tuple[int, ...]) -> None:
    """Refuse a .npy whose header declares another shape, before its data is allocated."""
    fmt = np.lib.format
    try:
        with open(path, "rb") as f:
            major, _ = fmt.read_magic(f)
            found = (fmt.read_array_header_1_0 if major == 1 else fmt.read_array_header_2_0)(f)[0]
    except (OSError, ValueError) as exc:
        raise FileFormatError(f"{path}: cannot read the round-trip times ({exc})") from None
    if found != shape:
        raise FileFormatError(f"{path}: shape {found} but the camera in {RIG_FILE} is {shape[1]}x{shape[0]}")


def load_ground_truth(folder: str | Path, *, shape: tuple[int, int] | None = None) -> dict | None:
    """``ground_truth.npz`` of a simulated capture as a dict of arrays, or None when absent.

    With ``shape`` (H, W), the maps ``range``, ``depth`` (float) and ``valid``, ``hit`` (bool) present in
    the file must have that shape and kind; FileFormatError naming the file otherwise (or when it cannot be
    read)."""
    path = Path(folder) / "ground_truth.npz"
    if not path.exists():
        return None
    try:
        with np.load(path) as z:
            truth = {k: z[k] for k in z.files}
    except Exception as exc:  # numpy and zipfile raise many types (ValueError, BadZipFile, EOFError...)
        raise FileFormatError(f"{path}: cannot read the ground truth ({type(exc).__name__}: {str(exc)[:200]}); "
                              "expected an .npz of maps, or no file") from None
    for key, kind in _TRUTH_MAPS.items():
        a = truth.get(key)
        if shape is not None and a is not None and (a.shape != tuple(shape) or a.dtype.kind != kind):
            raise FileFormatError(f"{path}: map '{key}' is {a.dtype} {a.shape}, expected "
                                  f"{'bool' if kind == 'b' else 'float'} {tuple(shape)} like the capture")
    return truth
