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

import warnings
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
        outside the mask (and where the file has a zero or NaN normal); None when the folder has no
        ``Normal_gt.mat``.
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
        If the folder or a listed file is missing or unreadable, or a name in ``filenames.txt`` leads out of
        the folder (an absolute path, ``..``, a symbolic link); if ``filenames.txt``, the light rows and
        the intensity rows disagree in count; if a light row is not unit length or an intensity is not
        positive; if the images, the mask or the normals differ in size; if the mask is empty or a mask pixel
        has no ground-truth normal; or if an image is not 16-bit RGB.
    """
    folder = Path(folder)
    if grey is not None and grey not in GREY_WEIGHTS:
        raise FileFormatError(f"load_diligent({folder}): grey must be one of {sorted(GREY_WEIGHTS)} or None, "
                              f"found {grey!r}")
    if not folder.is_dir():
        raise FileFormatError(f"{folder}: not a folder; expected a DiLiGenT object folder with filenames.txt, "
                              "light_directions.txt, light_intensities.txt, mask.png and the images")
    names = _read_names(folder / "filenames.txt")
    paths = [_inside(folder, name, folder / "filenames.txt") for name in names]
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
        return _read_image(paths[i], (H, W), intensities[i], weights)

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
    except UnicodeDecodeError as exc:
        raise FileFormatError(f"{path}: expected a text file of image names, found bytes that are not text "
                              f"({exc.reason} at byte {exc.start})") from exc
    if not names:
        raise FileFormatError(f"{path}: no image names; expected one PNG file name per line")
    return names


def _quote(text: str, limit: int = 200) -> str:
    """``repr`` of at most ``limit`` characters of ``text`` (a file may hold anything)."""
    return repr(text[:limit]) + (f" ({len(text)} characters)" if len(text) > limit else "")


def _inside(folder: Path, name: str, listing: Path) -> Path:
    """The file ``name`` (a line of ``listing``) in ``folder``, refused unless it stays inside the folder:
    no absolute path, no ``..``, no symbolic link leading out of it."""
    rel = Path(name)
    reason = None
    if "\0" in name:
        reason = "it contains a NUL character"
    elif rel.is_absolute():
        reason = "it is an absolute path"
    elif ".." in rel.parts:
        reason = "it climbs out with '..'"
    elif len(name) > 255:
        reason = "it is longer than a file name can be"
    if reason is None:
        try:
            target = (folder / rel).resolve()
            if not target.is_relative_to(folder.resolve()):
                reason = f"it is a symbolic link to {_quote(str(target))}, outside the folder"
        except (OSError, RuntimeError) as exc:  # a loop of links, a name the system refuses
            reason = f"it cannot be resolved ({exc})"
    if reason:
        raise FileFormatError(f"{listing}: image name {_quote(name)} is refused: {reason}; expected a file name "
                              f"inside {folder}")
    return folder / rel


def _read_rows(path: Path, n: int) -> np.ndarray:
    """(n, 3) float64 rows of a whitespace-separated text file."""
    if not path.is_file():
        raise FileFormatError(f"{path}: missing; expected {n} rows of 3 numbers, one per image in filenames.txt")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", UserWarning)  # "input contained no data": reported below
            rows = np.loadtxt(path, dtype=np.float64, ndmin=2)
    except ValueError as exc:
        raise FileFormatError(f"{path}: not a table of numbers ({str(exc)[:200]})") from exc
    if rows.shape != (n, 3) or not np.all(np.isfinite(rows)):
        raise FileFormatError(f"{path}: found {rows.shape[0]} rows of {rows.shape[1] if rows.ndim == 2 else 0} "
                              f"values, expected {n} rows of 3 finite numbers (one per image in filenames.txt)")
    return rows


def _imread(path: Path, what: str) -> np.ndarray:
    if path.is_dir():
        raise FileFormatError(f"{path}: is a folder; expected {what}")
    if not path.is_file():
        raise FileFormatError(f"{path}: missing; expected {what}")
    from rangekit.regular_files import read_regular_file

    data = read_regular_file(path, what=what)
    img = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED) if data else None
    if img is None:
        raise FileFormatError(f"{path}: not a readable image; expected {what}")
    return img


def _read_mask(path: Path) -> np.ndarray:
    m = _imread(path, "the object mask (non-zero = object)")
    if m.ndim == 3:
        m = m[..., :3].max(axis=2)
    if not np.any(m > 0):
        raise FileFormatError(f"{path}: the mask is empty (all {m.shape[1]}x{m.shape[0]} pixels are 0); expected "
                              "non-zero pixels on the object")
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
        variables = scipy.io.loadmat(str(path))
    except Exception as exc:  # scipy raises many types (TypeError, MatReadError, ValueError...) on a damaged file
        raise FileFormatError(f"{path}: not a readable MATLAB file ({type(exc).__name__}: {str(exc)[:200]}); "
                              "save it as MATLAB v7 or older (scipy cannot read v7.3/HDF5 files)") from exc
    if "Normal_gt" not in variables:
        found = [k for k in variables if not k.startswith("__")]
        raise FileFormatError(f"{path}: no variable 'Normal_gt', found {_quote(', '.join(found)) if found else 'none'}")
    raw = np.asarray(variables["Normal_gt"])
    if raw.dtype.kind not in "fiu" or raw.shape != mask.shape + (3,):
        raise FileFormatError(f"{path}: Normal_gt has shape {raw.shape}, expected {mask.shape + (3,)} like mask.png, "
                              f"and type {raw.dtype}, expected real numbers")
    N = raw.astype(np.float64) * _FLIP
    length = np.linalg.norm(N, axis=2)
    known = mask & np.isfinite(length) & (length > 0)
    if not known.any():
        raise FileFormatError(f"{path}: none of the {int(mask.sum())} mask pixels has a normal in Normal_gt (all "
                              "NaN, infinite or zero); expected unit normals on the object")
    with np.errstate(invalid="ignore", divide="ignore"):
        N /= length[..., None]
    N[~known] = np.nan  # outside the mask, and any mask pixel without a normal: not compared
    return N
