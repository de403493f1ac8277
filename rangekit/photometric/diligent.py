"""Reader for one object of the DiLiGenT photometric-stereo benchmark (Shi et al., CVPR 2016).

A DiLiGenT object folder holds ``filenames.txt`` (one 16-bit RGB PNG per line), ``light_directions.txt``
(one unit vector per image, towards the light), ``light_intensities.txt`` (one RGB row per image),
``mask.png`` and, for the benchmark objects, ``Normal_gt.mat`` (key ``Normal_gt``).

Frames: DiLiGenT's camera frame has x right, y **up**, z **towards the viewer**. rangekit uses the
OpenCV camera frame (x right, y down, z forward), so every vector is converted by
``(x, y, z) -> (x, -y, -z)``: lights on the camera's side get a negative z and normals seen by the
camera face it (negative z).

Benchmark recipe (what :func:`load_diligent` applies): divide each 16-bit image by 65535, divide each
RGB channel by that image's light intensity, then convert to grey with MATLAB ``rgb2gray`` weights
(ITU-R BT.601: 0.298936 R + 0.587043 G + 0.114021 B), the conversion of the DiLiGenT MATLAB baseline.
With it the least-squares (L2) baseline on ``ball`` scores 4.17 deg mean angular error (published
4.10); the plain channel mean scores 4.29 deg, which is why BT.601 is the default.
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from rangekit.errors import FileFormatError
from rangekit.image_header import check_image_files

__all__ = ["DiligentData", "load_diligent", "GREY_WEIGHTS"]

#: Grey conversions by name: RGB weights (sum 1). "rgb2gray" is MATLAB's (ITU-R BT.601).
GREY_WEIGHTS = {
    "rgb2gray": np.array([0.298936021293775, 0.587043074451121, 0.114020904255103]),
    "mean": np.full(3, 1.0 / 3.0),
}
_FLIP = np.array([1.0, -1.0, -1.0])  # DiLiGenT (x right, y up, z to viewer) -> OpenCV (x right, y down, z fwd)
_UNIT_TOL = 1e-2  # the files give 4 decimals; rows are unit to ~6e-5


@dataclass(frozen=True, eq=False, repr=False)
class DiligentData:
    """One DiLiGenT object, converted to rangekit conventions.

    images : (f, H, W) float32, or (f, H, W, 3) RGB when loaded with ``grey=None``. Linear radiance
        after the benchmark recipe (``/ 65535``, ``/`` the image's RGB light intensity, then grey).
    lights : (f, 3) float64 unit directions from the surface towards each light, OpenCV camera frame
        (renormalised to unit length after checking).
    intensities : (f, 3) float64 RGB light intensities as in ``light_intensities.txt`` (already divided out).
    mask : (H, W) bool, the object pixels.
    normals_gt : (H, W, 3) float64 unit normals, OpenCV camera frame (facing the camera: z < 0), NaN
        outside the mask; None when the folder has no ``Normal_gt.mat``.
    filenames : image file names in ``filenames.txt`` order (the order of ``images`` and ``lights``).
    grey : the grey conversion applied ("rgb2gray", "mean"), or None for RGB images.
    folder : the folder read.
    """

    images: np.ndarray
    lights: np.ndarray
    intensities: np.ndarray
    mask: np.ndarray
    normals_gt: np.ndarray | None
    filenames: tuple[str, ...]
    grey: str | None
    folder: Path

    def __repr__(self) -> str:
        f, H, W = self.images.shape[:3]
        return (f"DiligentData({self.folder.name!r}, {f} images {W}x{H}, grey={self.grey!r}, "
                f"mask_pixels={int(self.mask.sum())}, normals_gt={'yes' if self.normals_gt is not None else 'no'})")


def load_diligent(folder: str | Path, *, grey: str | None = "rgb2gray", workers: int = 4) -> DiligentData:
    """Read one DiLiGenT object folder and apply the benchmark recipe.

    Parameters
    ----------
    folder : path of the object folder (e.g. ``.../pmsData/ballPNG``).
    grey : {"rgb2gray", "mean"} or None, optional
        Grey conversion after the intensity division: MATLAB ``rgb2gray`` weights (the DiLiGenT baseline's
        choice, default), the plain channel mean, or None to keep (f, H, W, 3) RGB (three times the memory).
    workers : int
        Threads that read and convert the PNGs (OpenCV and numpy release the GIL).

    Returns
    -------
    DiligentData
        Images (f, H, W) float32, lights (f, 3) unit OpenCV camera frame, mask, ground-truth normals.

    Raises
    ------
    FileFormatError
        If the folder or a listed file is missing or unreadable; if ``filenames.txt``, the light rows and
        the intensity rows disagree in count; if a light row is not unit length or an intensity is not
        positive; if the images, the mask or the normals differ in size; or if an image is not 16-bit RGB.
    """
    folder = Path(folder)
    if grey is not None and grey not in GREY_WEIGHTS:
        raise FileFormatError(f"load_diligent({folder}): grey must be one of {sorted(GREY_WEIGHTS)} or None, "
                              f"found {grey!r}")
    if not folder.is_dir():
        raise FileFormatError(f"{folder}: not a folder; expected a DiLiGenT object folder with filenames.txt, "
                              "light_directions.txt, light_intensities.txt, mask.png and the images")
    names = _read_names(folder / "filenames.txt")
    lights = _read_rows(folder / "light_directions.txt", len(names))
    intensities = _read_rows(folder / "light_intensities.txt", len(names))
    norms = np.linalg.norm(lights, axis=1)
    bad = np.flatnonzero(np.abs(norms - 1.0) > _UNIT_TOL)
    if bad.size:
        raise FileFormatError(f"{folder / 'light_directions.txt'}: row {bad[0] + 1} has length {norms[bad[0]]:.4g}, "
                              f"expected unit directions (|length - 1| <= {_UNIT_TOL}); {bad.size} rows are off")
    if not np.all(intensities > 0):
        row = int(np.flatnonzero(~(intensities > 0).all(axis=1))[0])
        raise FileFormatError(f"{folder / 'light_intensities.txt'}: row {row + 1} is {intensities[row].tolist()}, "
                              "expected three positive RGB intensities")
    # The budget from the headers, before any pixel (float32 images, twice: the list and the stack).
    check_image_files([p for p in (folder / n for n in names) if p.is_file()], what="DiLiGenT images",
                      same_size=False, copies=2, bytes_per_pixel=4 * (3 if grey is None else 1))
    mask = _read_mask(folder / "mask.png")
    H, W = mask.shape
    weights = None if grey is None else GREY_WEIGHTS[grey].astype(np.float32)

    def read(i: int) -> np.ndarray:
        return _read_image(folder / names[i], (H, W), intensities[i], weights)

    with ThreadPoolExecutor(max_workers=max(1, int(workers))) as pool:
        images = np.stack(list(pool.map(read, range(len(names)))))
    return DiligentData(images=images, lights=(lights / norms[:, None]) * _FLIP, intensities=intensities,
                        mask=mask, normals_gt=_read_normals(folder / "Normal_gt.mat", mask),
                        filenames=tuple(names), grey=grey, folder=folder)


def _read_names(path: Path) -> list[str]:
    try:
        names = [line.strip() for line in path.read_text().splitlines() if line.strip()]
    except OSError as exc:
        raise FileFormatError(f"{path}: cannot read the image list ({exc.strerror or exc})") from exc
    if not names:
        raise FileFormatError(f"{path}: no image names; expected one PNG file name per line")
    return names


def _read_rows(path: Path, n: int) -> np.ndarray:
    """(n, 3) float64 rows of a whitespace-separated text file."""
    if not path.is_file():
        raise FileFormatError(f"{path}: missing; expected {n} rows of 3 numbers, one per image in filenames.txt")
    try:
        rows = np.loadtxt(path, dtype=np.float64, ndmin=2)
    except ValueError as exc:
        raise FileFormatError(f"{path}: not a table of numbers ({exc})") from exc
    if rows.shape != (n, 3) or not np.all(np.isfinite(rows)):
        raise FileFormatError(f"{path}: found {rows.shape[0]} rows of {rows.shape[1] if rows.ndim == 2 else 0} "
                              f"values, expected {n} rows of 3 finite numbers (one per image in filenames.txt)")
    return rows


def _imread(path: Path, what: str) -> np.ndarray:
    if not path.is_file():
        raise FileFormatError(f"{path}: missing; expected {what}")
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise FileFormatError(f"{path}: not a readable image")
    return img


def _read_mask(path: Path) -> np.ndarray:
    m = _imread(path, "the object mask (non-zero = object)")
    if m.ndim == 3:
        m = m[..., :3].max(axis=2)
    return m > 0


def _read_image(path: Path, shape: tuple[int, int], intensity: np.ndarray, weights: np.ndarray | None):
    """One capture after the recipe: (H, W) float32 grey, or (H, W, 3) RGB."""
    raw = _imread(path, "a 16-bit RGB PNG (listed in filenames.txt)")
    if raw.ndim != 3 or raw.shape[2] not in (3, 4) or raw.dtype != np.uint16:
        raise FileFormatError(f"{path}: expected a 16-bit RGB PNG, found shape {raw.shape} dtype {raw.dtype}")
    if raw.shape[:2] != shape:
        raise FileFormatError(f"{path}: image is {raw.shape[1]}x{raw.shape[0]}, expected {shape[1]}x{shape[0]} "
                              "like mask.png")
    rgb = raw[..., 2::-1].astype(np.float32)  # BGR(A) -> RGB
    scale = (1.0 / (65535.0 * intensity)).astype(np.float32)  # (3,): / 65535, / light intensity per channel
    if weights is None:
        return rgb * scale
    return rgb @ (scale * weights)


def _read_normals(path: Path, mask: np.ndarray) -> np.ndarray | None:
    if not path.exists():
        return None
    import scipy.io  # imported here: only the ground truth needs it

    try:
        N = np.asarray(scipy.io.loadmat(str(path))["Normal_gt"], dtype=np.float64)
    except KeyError as exc:
        raise FileFormatError(f"{path}: no variable 'Normal_gt'") from exc
    except (ValueError, OSError, NotImplementedError) as exc:
        raise FileFormatError(f"{path}: not a readable MATLAB file ({exc}); save it as MATLAB v7 or older "
                              "(scipy cannot read v7.3/HDF5 files)") from exc
    if N.shape != mask.shape + (3,):
        raise FileFormatError(f"{path}: Normal_gt has shape {N.shape}, expected {mask.shape + (3,)} like mask.png")
    N = N * _FLIP
    with np.errstate(invalid="ignore", divide="ignore"):
        N /= np.linalg.norm(N, axis=2, keepdims=True)
    N[~mask] = np.nan
    return N
