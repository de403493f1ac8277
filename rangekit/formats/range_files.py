"""Range-sensor folders on disk: reading a ToF capture and a simulated capture's ground truth.

A ToF capture folder (``rangekit sim render --sensor tof|tof-pulsed``, or a real sensor's dump in
the same layout) holds:

* ``tof.json``: ``kind`` ``rangekit.tof.cw/1`` with ``plan`` (``frequencies_hz``, ``steps_rad``),
  ``electrons_per_dn``, ``read_noise_e``, ``saturation_dn``; or ``rangekit.tof.pulsed/1``.
* ``rig.json``: the ToF camera as ``cameras[0]`` (a rig file, docs/rig.md).
* CW: ``samples/000.png ...``: 16-bit raw correlation samples, frequency-major (all phase steps of
  the first frequency, then the next). Pulsed: ``round_trip_s.npy`` (seconds, NaN where no return).
* optionally ``ground_truth.npz`` (range, depth, xyz, hit, valid) from the simulator.

The depth outputs of ``rangekit tof`` and ``rangekit stereo`` are written by
:func:`rangekit.app.range_runs.write_depth_outputs`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.formats.capture import list_images, read_stack
from rangekit.errors import FileFormatError, InputError
from rangekit.image_header import check_image_files
from rangekit.io import read_json
from rangekit.rig import load_rig
from rangekit.tof import FrequencyPlan

__all__ = ["ToFFolder", "load_tof_folder", "load_ground_truth"]

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
        raise FileFormatError(f"{folder}: not a folder (expected a ToF capture folder with tof.json, rig.json and "
                              "samples/)")
    meta = read_json(folder / "tof.json", what="ToF capture description")
    kind = meta.get("kind")
    if kind not in TOF_KINDS:
        raise FileFormatError(f"{folder / 'tof.json'}: 'kind' must be one of {', '.join(TOF_KINDS)}, found {kind!r}")
    rig = load_rig(folder / "rig.json")
    cam = rig.camera
    if kind == "rangekit.tof.pulsed/1":
        path = folder / "round_trip_s.npy"
        _check_npy_shape(path, (cam.height, cam.width))
        try:
            dt = np.load(path)
        except (OSError, ValueError) as exc:
            raise FileFormatError(f"{path}: cannot read the round-trip times ({exc})") from None
        if dt.shape != (cam.height, cam.width):
            raise FileFormatError(f"{path}: shape {dt.shape} but the camera in rig.json is {cam.width}x{cam.height}")
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
    headers = check_image_files(files, what="ToF raw samples", copies=2)  # read_stack's list, then np.stack
    if headers and headers[0] is not None and (headers[0].width, headers[0].height) != (cam.width, cam.height):
        raise FileFormatError(f"{files[0]}: samples are {headers[0].width}x{headers[0].height} (width x height) "
                              f"but the camera in rig.json is {cam.width}x{cam.height}")
    stack = np.stack(read_stack(files, what="ToF raw samples"))
    if stack.ndim != 3 or stack.shape[1:] != (cam.height, cam.width):
        raise FileFormatError(f"{folder / 'samples'}: samples are {stack.shape[1:][::-1]} (width, height) but the "
                              f"camera in rig.json is {cam.width}x{cam.height}")
    g = float(meta.get("electrons_per_dn", 1.0))
    rn = float(meta.get("read_noise_e", 0.0))
    sat = meta.get("saturation_dn")
    return ToFFolder(folder, kind, cam, plan, stack, None, g, rn, None if sat is None else float(sat))


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
        raise FileFormatError(f"{path}: shape {found} but the camera in rig.json is {shape[1]}x{shape[0]}")


def load_ground_truth(folder: str | Path) -> dict | None:
    """``ground_truth.npz`` of a simulated capture as a dict of arrays, or None when absent."""
    path = Path(folder) / "ground_truth.npz"
    if not path.exists():
        return None
    with np.load(path) as z:
        return {k: z[k] for k in z.files}
