"""``rangekit photometric`` on bad DiLiGenT-style folders: corrupt Normal_gt.mat, black images, bad light
files, image names that leave the folder, bad masks, degenerate uncalibrated input. Each ends in one
``rangekit: error:`` line naming the file (or folder) with the expected and found value, and no output
folder is created; the outputs and ``PinholeCamera.save`` are written atomically."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
import scipy.io

from support.cli_runs import assert_error

H = W = 24
N_LIGHTS = 8


def _sphere() -> tuple[np.ndarray, np.ndarray]:
    """(H, W) mask and (H, W, 3) normals of a sphere in DiLiGenT's frame (y up, z towards the viewer)."""
    v, u = np.mgrid[0:H, 0:W]
    x, y = (u - (W - 1) / 2) / (W / 2 - 2), -(v - (H - 1) / 2) / (H / 2 - 2)
    r2 = x ** 2 + y ** 2
    mask = r2 < 1
    return mask, np.stack([x, y, np.sqrt(np.clip(1 - r2, 0, 1))], -1) * mask[..., None]


@pytest.fixture(scope="module")
def good(tmp_path_factory) -> Path:
    """A tiny Lambertian sphere in the DiLiGenT layout: 8 16-bit images of 24x24, lights at two elevations."""
    folder = tmp_path_factory.mktemp("ps") / "sphere"
    folder.mkdir()
    mask, N = _sphere()
    az = np.linspace(0, 2 * np.pi, N_LIGHTS, endpoint=False)
    el = np.where(np.arange(N_LIGHTS) % 2 == 0, 0.45, 0.8)
    L = np.column_stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    for i, light in enumerate(L):
        img = np.clip(N @ light, 0, None) * 0.8
        cv2.imwrite(str(folder / f"{i:03d}.png"), np.rint(np.repeat(img[..., None], 3, 2) * 65535).astype(np.uint16))
    (folder / "filenames.txt").write_text("".join(f"{i:03d}.png\n" for i in range(N_LIGHTS)))
    np.savetxt(folder / "light_directions.txt", L, fmt="%.6f")
    np.savetxt(folder / "light_intensities.txt", np.ones((N_LIGHTS, 3)), fmt="%.4f")
    cv2.imwrite(str(folder / "mask.png"), mask.astype(np.uint8) * 255)
    scipy.io.savemat(str(folder / "Normal_gt.mat"), {"Normal_gt": N})
    return folder


@pytest.fixture
def folder(good, tmp_path) -> Path:
    return Path(shutil.copytree(good, tmp_path / "obj"))


def _run(cli, folder: Path, method: str = "ls"):
    return cli("photometric", folder, "--method", method, "--out", folder.parent / "out")


def test_the_good_folder_is_good(cli, folder):
    run = _run(cli, folder, "robust")
    assert run.code == 0, run.err
    assert "angular error against Normal_gt.mat: mean 0.0" in run.out  # exact images: exact normals
    assert sorted(p.name for p in (folder.parent / "out").iterdir()) == [
        "albedo.png", "depth.npy", "mesh.ply", "normals.npy", "normals.png"]


@pytest.mark.parametrize("method", ["ls", "robust", "uncalibrated"])
def test_black_images_carry_no_light(cli, folder, method):
    for i in range(N_LIGHTS):
        cv2.imwrite(str(folder / f"{i:03d}.png"), np.zeros((H, W, 3), np.uint16))
    assert_error(_run(cli, folder, method), 1, str(folder), "all 8 images are black", "carry no light")
    assert not (folder.parent / "out").exists()


def _mat(variables):
    return lambda f: scipy.io.savemat(str(f / "Normal_gt.mat"), variables)


def _bytes(name, data):
    return lambda f: (f / name).write_bytes(data(f / name) if callable(data) else data)


BREAKAGES = {
    "mat_random_bytes": (_bytes("Normal_gt.mat", os.urandom(500)), "Normal_gt.mat", ["not a readable MATLAB file"]),
    "mat_header_then_garbage": (_bytes("Normal_gt.mat", lambda p: p.read_bytes()[:128] + b"\xff" * 300),
                                "Normal_gt.mat", ["not a readable MATLAB file"]),
    "mat_truncated": (_bytes("Normal_gt.mat", lambda p: p.read_bytes()[:300]), "Normal_gt.mat",
                      ["not a readable MATLAB file"]),
    "mat_empty": (_bytes("Normal_gt.mat", b""), "Normal_gt.mat", ["not a readable MATLAB file"]),
    "mat_wrong_variable": (_mat({"N": np.zeros((H, W, 3))}), "Normal_gt.mat", ["no variable 'Normal_gt'", "'N'"]),
    "mat_wrong_shape": (_mat({"Normal_gt": np.zeros((H, W))}), "Normal_gt.mat",
                        ["shape (24, 24), expected (24, 24, 3) like mask.png"]),
    "mat_text": (_mat({"Normal_gt": "hello"}), "Normal_gt.mat", ["type <U5, expected real numbers"]),
    "mat_complex": (_mat({"Normal_gt": np.ones((H, W, 3)) * 1j}), "Normal_gt.mat", ["complex128"]),
    "mat_all_zero": (_mat({"Normal_gt": np.zeros((H, W, 3))}), "Normal_gt.mat",
                     ["none of the 316 mask pixels has a normal"]),
    "lights_count": (_bytes("light_directions.txt", b"0 0 1\n" * 7), "light_directions.txt",
                     ["found 7 rows of 3 values, expected 8 rows"]),
    "lights_nan": (_bytes("light_directions.txt", b"nan 0 1\n" * 8), "light_directions.txt", ["3 finite numbers"]),
    "lights_zero": (_bytes("light_directions.txt", b"0 0 0\n" * 8), "light_directions.txt",
                    ["row 1 has length 0", "expected unit directions"]),
    "lights_text": (_bytes("light_directions.txt", b"0 0 1\n" * 7 + b"up up up\n"), "light_directions.txt",
                    ["not a table of numbers", "'up'"]),
    "lights_empty": (_bytes("light_directions.txt", b""), "light_directions.txt", ["found 0 rows"]),
    "intensities_nan": (_bytes("light_intensities.txt", b"1 nan 1\n" * 8), "light_intensities.txt",
                        ["3 finite numbers"]),
    "intensities_zero": (_bytes("light_intensities.txt", b"1 1 1\n" * 7 + b"0 0 0\n"), "light_intensities.txt",
                         ["row 8", "three positive RGB intensities"]),
    "intensities_count": (_bytes("light_intensities.txt", b"1 1 1\n" * 9), "light_intensities.txt",
                          ["found 9 rows"]),
    "names_binary": (_bytes("filenames.txt", b"\xff\xfe\x00" * 30), "filenames.txt",
                     ["expected a text file of image names"]),
    "names_count": (_bytes("filenames.txt", b"000.png\n001.png\n"), "light_directions.txt",
                    ["found 8 rows of 3 values, expected 2 rows"]),
    "mask_other_size": (lambda f: cv2.imwrite(str(f / "mask.png"), np.full((20, W), 255, np.uint8)), "000.png",
                        ["image is 24x24, expected 24x20 like mask.png"]),
    "mask_empty": (lambda f: cv2.imwrite(str(f / "mask.png"), np.zeros((H, W), np.uint8)), "mask.png",
                   ["the mask is empty"]),
    "mask_garbage": (_bytes("mask.png", b"\x89PNG garbage"), "mask.png", ["not a readable image"]),
    "image_truncated": (_bytes("003.png", lambda p: p.read_bytes()[:100]), "003.png", ["not a readable image"]),
    "image_8_bit": (lambda f: cv2.imwrite(str(f / "005.png"), np.zeros((H, W, 3), np.uint8)), "005.png",
                    ["expected a 16-bit RGB PNG", "uint8"]),
}


@pytest.mark.parametrize("name", list(BREAKAGES))
def test_a_broken_folder_is_a_clear_error(cli, folder, name):
    breakage, culprit, mentions = BREAKAGES[name]
    breakage(folder)
    assert_error(_run(cli, folder), 1, f"{folder}/{culprit}", *mentions)
    assert not (folder.parent / "out").exists()


def _escape_absolute(f: Path) -> str:
    return str((f / "000.png").resolve())


def _escape_dotdot(f: Path) -> str:
    shutil.copy(f / "000.png", f.parent / "outside.png")
    return "../outside.png"


def _escape_symlink(f: Path) -> str:
    shutil.move(f / "000.png", f.parent / "outside.png")
    (f / "000.png").symlink_to((f.parent / "outside.png").resolve())
    return "000.png"


@pytest.mark.parametrize("escape, reason", [
    (_escape_absolute, "it is an absolute path"),
    (_escape_dotdot, "it climbs out with '..'"),
    (_escape_symlink, "outside the folder"),
    (lambda f: "a\0b.png", "NUL character"),
    (lambda f: "x" * 5000, "(5000 characters)"),
])
def test_image_names_are_resolved_inside_the_folder(cli, folder, escape, reason):
    first = escape(folder)
    names = [first] + [f"{i:03d}.png" for i in range(1, N_LIGHTS)]
    (folder / "filenames.txt").write_text("\n".join(names) + "\n")
    line = assert_error(_run(cli, folder), 1, f"{folder}/filenames.txt", "is refused", reason)
    assert len(line) < 700  # a hostile name is quoted, not echoed whole
    assert not (folder.parent / "out").exists()


def test_a_symlink_inside_the_folder_is_followed(cli, folder):
    shutil.move(folder / "000.png", folder / "real.png")
    (folder / "000.png").symlink_to("real.png")
    assert _run(cli, folder).code == 0


@pytest.mark.parametrize("breakage, mentions", [
    ("identical", ["vary with the light in fewer than 3 independent ways", "rank 1 < 3"]),
    ("tiny_mask", ["at least 6 mask pixels whose four neighbours are in the mask", "found 0"]),
])
def test_uncalibrated_on_degenerate_input_is_a_clear_error(cli, folder, breakage, mentions):
    if breakage == "identical":
        for i in range(1, N_LIGHTS):
            shutil.copy(folder / "000.png", folder / f"{i:03d}.png")
    else:
        mask = np.zeros((H, W), np.uint8)
        mask[11:13, 11:13] = 255
        cv2.imwrite(str(folder / "mask.png"), mask)
        (folder / "Normal_gt.mat").unlink()
    assert_error(_run(cli, folder, "uncalibrated"), 1, str(folder), *mentions)
    assert not (folder.parent / "out").exists()


def test_a_one_pixel_mask_integrates(cli, folder):
    """Integration of isolated pixels pinned them with a NaN weight: 'Factor is exactly singular'."""
    mask = np.zeros((H, W), np.uint8)
    mask[12, 12] = 255
    cv2.imwrite(str(folder / "mask.png"), mask)
    run = _run(cli, folder)
    assert run.code == 0, run.err
    depth = np.load(folder.parent / "out" / "depth.npy")
    assert np.isfinite(depth).sum() == 1 and depth[12, 12] == 0


def test_photometric_outputs_are_written_atomically(cli, folder, monkeypatch):
    import rangekit.io

    written = []
    real = rangekit.io.atomic_write_with       # every atomic write goes through it (atomic_write_bytes too)
    monkeypatch.setattr(rangekit.io, "atomic_write_with", lambda p, w: (written.append(Path(p).name), real(p, w)))
    assert _run(cli, folder).code == 0
    assert sorted(written) == ["albedo.png", "depth.npy", "mesh.ply", "normals.npy", "normals.png"]
    assert not [p for p in (folder.parent / "out").iterdir() if p.name.endswith(".tmp")]


def test_camera_save_is_atomic(tmp_path, monkeypatch):
    """A failure while the camera file is written leaves the previous file whole and no temporary file."""
    import rangekit.io
    from rangekit.camera import PinholeCamera

    cam = PinholeCamera(np.array([[100.0, 0, 32], [0, 100, 24], [0, 0, 1]]), 64, 48, name="c")
    path = tmp_path / "cam.json"
    cam.save(path)
    before = path.read_bytes()

    def full_disk(fd):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(rangekit.io.os, "fsync", full_disk)
    with pytest.raises(OSError):
        PinholeCamera(np.array([[200.0, 0, 32], [0, 200, 24], [0, 0, 1]]), 64, 48, name="c").save(path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["cam.json"]
