"""rangekit.photometric.diligent: the DiLiGenT reader against the real ``ball`` object and against broken folders."""

from pathlib import Path

import cv2
import numpy as np
import pytest

from rangekit.photometric.diligent import load_diligent
from rangekit.errors import FileFormatError



@pytest.fixture(scope="module")
def ball():
    from support.shared_data import require_shared

    return load_diligent(require_shared("diligent-ball", "filenames.txt").parent)


def _angles_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1.0, 1.0)))


def test_ball_shapes_frames_and_mask(ball):
    assert ball.images.shape == (96, 512, 612) and ball.images.dtype == np.float32
    assert ball.lights.shape == (96, 3) and ball.mask.shape == (512, 612)
    assert ball.filenames[0] == "001.png" and ball.filenames[-1] == "096.png"
    assert int(ball.mask.sum()) == 15791
    np.testing.assert_allclose(np.linalg.norm(ball.lights, axis=1), 1.0, atol=1e-12)
    assert np.all(ball.lights[:, 2] < -0.7)  # every light is on the camera's side (OpenCV z forward)
    # DiLiGenT's first light is below the ball (its y < 0, y up): in OpenCV (y down) its y is positive.
    assert ball.lights[0, 1] > 0.4
    n = ball.normals_gt
    assert n.shape == (512, 612, 3)
    assert np.all(np.isnan(n[~ball.mask])) and np.all(np.isfinite(n[ball.mask]))
    np.testing.assert_allclose(np.linalg.norm(n[ball.mask], axis=1), 1.0, atol=1e-9)
    assert np.all(n[ball.mask][:, 2] <= 0) and np.mean(n[ball.mask][:, 2]) < -0.5  # facing the camera
    rows = np.flatnonzero(ball.mask.any(axis=1))
    top = n[rows[0], ball.mask[rows[0]]]
    assert np.all(top[:, 1] < -0.9)  # top of the image: the normal points up, i.e. -y in OpenCV
    img = ball.images[:, ball.mask]
    assert np.all(img >= 0) and 0.05 < np.median(img) < 2.0


def test_ball_least_squares_baseline(ball):
    """The L2 baseline reproduces the published 4.10 deg (Shi et al. 2016) within 0.1 deg: ours is 4.17."""
    B = ball.images[:, ball.mask].astype(np.float64)  # (f, N)
    X = np.linalg.lstsq(ball.lights, B, rcond=None)[0].T  # (N, 3) albedo-scaled normals
    n = X / np.linalg.norm(X, axis=1, keepdims=True)
    err = _angles_deg(n, ball.normals_gt[ball.mask]).mean()
    assert abs(err - 4.10) < 0.1, err
    assert abs(err - 4.175) < 0.01, err  # this loader's recipe exactly (rgb2gray after intensity division)


def test_ball_with_rangekit_photometric(ball):
    """Issue 8 acceptance on the real benchmark: least squares 4.1 +- 0.1 deg, robust at most 2.5 deg."""
    from rangekit.photometric import angular_error, photometric_stereo

    ls = photometric_stereo(ball.images, ball.lights, ball.mask, method="ls")
    rob = photometric_stereo(ball.images, ball.lights, ball.mask, method="robust")
    e_ls = angular_error(ls.normals, ball.normals_gt, ball.mask).mean_deg
    e_rob = angular_error(rob.normals, ball.normals_gt, ball.mask).mean_deg
    assert abs(e_ls - 4.10) < 0.1, e_ls          # measured 4.175
    assert e_rob <= 2.5, e_rob                   # measured 1.969


def test_photometric_command_on_the_ball(ball, tmp_path, capsys):
    from rangekit.cli import main

    assert main(["photometric", str(ball.folder), "--out", str(tmp_path / "ball"), "--method", "ls"]) == 0
    out = capsys.readouterr().out
    assert "mean 4.17" in out
    n = np.load(tmp_path / "ball" / "normals.npy")
    assert n.shape == ball.mask.shape + (3,) and np.all(np.isnan(n[~ball.mask]))
    assert np.nanmean(n[..., 2]) < 0


# --- broken folders ---------------------------------------------------------------------------------

def _fake(tmp_path: Path, n: int = 3, size=(6, 5)) -> Path:
    H, W = size
    rng = np.random.default_rng(0)
    for i in range(n):
        cv2.imwrite(str(tmp_path / f"{i:03d}.png"), rng.integers(0, 65535, (H, W, 3), dtype=np.uint16))
    (tmp_path / "filenames.txt").write_text("".join(f"{i:03d}.png\n" for i in range(n)))
    L = np.array([[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.0, -0.6, 0.8], [0.6, 0.0, 0.8]])[:n]
    np.savetxt(tmp_path / "light_directions.txt", L, fmt="%.4f")
    np.savetxt(tmp_path / "light_intensities.txt", np.full((n, 3), 2.0), fmt="%.4f")
    mask = np.zeros((H, W), np.uint8)
    mask[1:-1, 1:-1] = 255
    cv2.imwrite(str(tmp_path / "mask.png"), mask)
    return tmp_path


def test_fake_folder_recipe_and_frames(tmp_path):
    d = load_diligent(_fake(tmp_path))
    assert d.images.shape == (3, 6, 5) and d.normals_gt is None and d.mask.sum() == 12
    np.testing.assert_allclose(d.lights[1], [0.6, 0.0, -0.8])
    np.testing.assert_allclose(d.lights[2], [0.0, 0.6, -0.8])
    raw = cv2.imread(str(tmp_path / "001.png"), cv2.IMREAD_UNCHANGED)[..., ::-1].astype(np.float64)
    expect = raw @ np.array([0.298936021293775, 0.587043074451121, 0.114020904255103]) / 65535 / 2.0
    np.testing.assert_allclose(d.images[1], expect, rtol=1e-5)
    rgb = load_diligent(tmp_path, grey=None)
    assert rgb.images.shape == (3, 6, 5, 3)
    np.testing.assert_allclose(rgb.images[1], raw / 65535 / 2.0, rtol=1e-6)
    np.testing.assert_allclose(load_diligent(tmp_path, grey="mean").images[1], raw.mean(axis=2) / 65535 / 2.0,
                               rtol=1e-5)


def test_fake_folder_normals_gt(tmp_path):
    import scipy.io

    _fake(tmp_path)
    N = np.zeros((6, 5, 3))
    N[1:-1, 1:-1] = [0.0, 0.6, 0.8]
    scipy.io.savemat(str(tmp_path / "Normal_gt.mat"), {"Normal_gt": N})
    d = load_diligent(tmp_path)
    np.testing.assert_allclose(d.normals_gt[2, 2], [0.0, -0.6, -0.8])
    assert np.isnan(d.normals_gt[0, 0]).all()
    scipy.io.savemat(str(tmp_path / "Normal_gt.mat"), {"Normal_gt": N[:4]})
    with pytest.raises(FileFormatError, match=r"Normal_gt\.mat.*shape \(4, 5, 3\), expected \(6, 5, 3\)"):
        load_diligent(tmp_path)


@pytest.mark.parametrize("breakage, match", [
    ("missing_list", r"filenames\.txt: cannot read"),
    ("missing_image", r"002\.png: missing"),
    ("missing_mask", r"mask\.png: missing"),
    ("missing_intensities", r"light_intensities\.txt: missing"),
    ("count", r"light_directions\.txt: found 2 rows of 3 values, expected 3 rows"),
    ("not_unit", r"light_directions\.txt: row 2 has length 1\.2"),
    ("size", r"001\.png: image is 4x6, expected 5x6"),
    ("eight_bit", r"000\.png: expected a 16-bit RGB PNG"),
    ("not_a_folder", r"not a folder"),
    ("bad_intensity", r"light_intensities\.txt: row 3 .* positive"),
])
def test_bad_folders(tmp_path, breakage, match):
    folder = _fake(tmp_path)
    if breakage == "missing_list":
        (folder / "filenames.txt").unlink()
    elif breakage == "missing_image":
        (folder / "002.png").unlink()
    elif breakage == "missing_mask":
        (folder / "mask.png").unlink()
    elif breakage == "missing_intensities":
        (folder / "light_intensities.txt").unlink()
    elif breakage == "count":
        np.savetxt(folder / "light_directions.txt", [[0, 0, 1], [0, 0, 1]])
    elif breakage == "not_unit":
        np.savetxt(folder / "light_directions.txt", [[0, 0, 1], [0, 0, 1.2], [0, 0, 1]])
    elif breakage == "size":
        cv2.imwrite(str(folder / "001.png"), np.zeros((6, 4, 3), np.uint16))
    elif breakage == "eight_bit":
        cv2.imwrite(str(folder / "000.png"), np.zeros((6, 5, 3), np.uint8))
    elif breakage == "not_a_folder":
        folder = folder / "nothing-here"
    elif breakage == "bad_intensity":
        np.savetxt(folder / "light_intensities.txt", [[1, 1, 1], [1, 1, 1], [1, 0, 1]])
    with pytest.raises(FileFormatError, match=match):
        load_diligent(folder)
