"""Nothing hangs or eats the machine: the memory budget, image headers read before any pixel, and
image stacks of every kind refused from their headers. (Sizes of patterns, boards, rig cameras, voxels,
renders, simulated sensors and ToF plans: test_limits_sizes.py.) Each refusal names the input, what was expected and what was found; options exit 2,
file contents exit 1, and no output is written."""

from __future__ import annotations

import io
import json
import struct
import zlib

import cv2
import numpy as np
import pytest

from support.cli_runs import assert_error
from rangekit.budget import (ENV_VAR, array_bytes, cgroup_memory_limit, check_budget, format_bytes, memory_budget,
                             parse_bytes, physical_memory)
from rangekit.errors import BudgetError, BudgetUsageError, FileFormatError, UsageError
from rangekit.formats.capture import load_capture, read_stack
from rangekit.formats.range_files import load_tof_folder
from rangekit.image_header import check_image_files, read_image_header
from rangekit.io import read_png
from rangekit.rig.rig_file import Rig, save_rig, template_rig

BIG = 20000  # pixels per side of the huge images the issue describes (44 of them: 7 GB and more)


# ----------------------------------------------------------------------------- helpers
def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_header(path, width: int, height: int, *, bits: int = 8, colour: int = 0) -> None:
    """A PNG cut after its IHDR chunk: the header of a ``width`` x ``height`` image, no pixels (33 bytes)."""
    ihdr = struct.pack(">IIBBBBB", width, height, bits, colour, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr))


def _huge_folder(folder, n: int = 44, *, bits: int = 8, colour: int = 0):
    folder.mkdir()
    for k in range(n):
        png_header(folder / f"{k:03d}.png", BIG, BIG, bits=bits, colour=colour)
    return folder


# ----------------------------------------------------------------------------- the budget
@pytest.mark.parametrize("text, expected", [
    ("8G", 8 * 2**30), ("512MiB", 512 * 2**20), ("1.5g", int(1.5 * 2**30)), ("2000000000", 2000000000),
    ("64 kB", 65536), ("2T", 2 * 2**40),
])
def test_budget_sizes_parse(text, expected):
    assert parse_bytes(text) == expected


@pytest.mark.parametrize("text", ["", "abc", "-1G", "0", "1e400", "nan", "5X", "0.1"])
def test_a_bad_budget_variable_is_a_usage_error_naming_it(text):
    with pytest.raises(UsageError, match=f"{ENV_VAR}={text!r}.*expected a memory size"):
        parse_bytes(text)


def test_the_default_budget_is_half_the_memory_or_the_cgroup_limit(monkeypatch):
    monkeypatch.delenv(ENV_VAR, raising=False)
    limit = cgroup_memory_limit()
    assert memory_budget() == min(physical_memory(), limit or physical_memory()) // 2
    monkeypatch.setenv(ENV_VAR, "3M")
    assert memory_budget() == 3 * 2**20


def test_cgroup_limits_v2_and_v1(tmp_path):
    (tmp_path / "grp").mkdir()
    (tmp_path / "memory.max").write_text("max\n")
    (tmp_path / "grp" / "memory.max").write_text("1073741824\n")
    proc = tmp_path / "cgroup"
    proc.write_text("0::/grp\n")
    assert cgroup_memory_limit(tmp_path, proc) == 2**30
    v1 = tmp_path / "v1"
    (v1 / "memory").mkdir(parents=True)
    (v1 / "memory" / "memory.limit_in_bytes").write_text("9223372036854771712\n")  # v1's "no limit"
    assert cgroup_memory_limit(v1, tmp_path / "missing") is None
    (v1 / "memory" / "memory.limit_in_bytes").write_text("536870912\n")
    assert cgroup_memory_limit(v1, tmp_path / "missing") == 2**29


def test_check_budget_names_what_the_need_and_the_budget(budget):
    budget("1M")
    check_budget(2**20, "exactly the budget")
    with pytest.raises(BudgetError, match=r"the thing needs 1 MiB .* budget of 1 MiB \(set by RANGEKIT_MEMORY"):
        check_budget(2**20 + 1, "the thing")
    with pytest.raises(BudgetUsageError, match=r"^--size 9x9: the thing needs") as err:
        check_budget(2**21, "the thing", option="--size 9x9")
    assert isinstance(err.value, UsageError) and array_bytes((2**40, 2**40, 3), 8) == 3 * 2**83


# ----------------------------------------------------------------------------- image headers
_LAYOUTS = [((5, 7), np.uint8), ((5, 7, 3), np.uint8), ((5, 7), np.uint16), ((5, 7, 3), np.uint16),
            ((5, 7, 4), np.uint8)]


@pytest.mark.parametrize("suffix, shape, dtype", [
    (suffix, shape, dtype) for suffix in (".png", ".tif", ".tiff", ".bmp", ".pgm", ".ppm") for shape, dtype in _LAYOUTS
    if not (suffix == ".pgm" and len(shape) == 3 or suffix == ".ppm" and shape[2:] != (3,))])
def test_headers_give_the_size_and_depth_read_png_returns(tmp_path, suffix, shape, dtype):
    img = (np.arange(np.prod(shape)) % 200).astype(dtype).reshape(shape)
    path = tmp_path / f"im{suffix}"
    assert cv2.imwrite(str(path), img)
    back = read_png(path)
    h = read_image_header(path)
    assert (h.width, h.height) == (back.shape[1], back.shape[0])
    assert h.bits == 8 * back.dtype.itemsize
    assert h.nbytes >= back.nbytes and (h.nbytes == back.nbytes or suffix == ".bmp")


@pytest.mark.parametrize("data, problem", [
    (b"\x89PNG\r\n\x1a\n\x00\x00\x00\x0dIHDR\x00\x00", "cut short"),
    (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", struct.pack(">IIBBBBB", 0, 10, 8, 0, 0, 0, 0)), "zero size"),
    (b"BM\x00\x00", "BMP"),
    (b"P5\n# only a comment\n", "PNM"),
    (b"II*\x00\xff\xff\xff\x7f", "TIFF"),
])
def test_damaged_headers_are_file_format_errors(tmp_path, no_pixels, data, problem):
    path = tmp_path / "bad.png"
    path.write_bytes(data)
    with pytest.raises(FileFormatError, match=problem):
        read_png(path)


def test_44_huge_pngs_are_refused_from_their_headers(cli, tmp_path, budget, no_pixels):
    folder = _huge_folder(tmp_path / "cap")
    run = cli("decode", folder, "--pattern", "graycode", "--projector", "1280x800", "--out", tmp_path / "m.npz")
    need = format_bytes(44 * BIG * BIG + 2 * BIG * BIG)
    assert_error(run, 1, str(folder), "44 image(s)", f"{BIG}x{BIG}", f"needs {need}", "budget of 4 GiB")
    assert not (tmp_path / "m.npz").exists()


def test_a_huge_capture_folder_is_refused_before_loading(tmp_path, budget, no_pixels):
    folder = _huge_folder(tmp_path / "cap", 10, bits=16, colour=2)
    (folder / "patterns.json").write_text(json.dumps({"method": "white", "width": 64, "height": 40}))
    with pytest.raises(BudgetError, match=f"10 image\\(s\\) of {BIG}x{BIG} 3-channel 16-bit"):
        load_capture(folder)


def test_a_single_huge_image_is_refused_from_its_header(tmp_path, budget, no_pixels):
    png_header(tmp_path / "one.png", 60000, 60000, bits=16, colour=6)
    with pytest.raises(BudgetError, match=r"one\.png: 1 image\(s\) of 60000x60000 3-channel 16-bit"):
        read_png(tmp_path / "one.png")


@pytest.mark.parametrize("second, found", [((65, 48, 8), "65x48 1-channel 8-bit"),
                                           ((64, 48, 16), "64x48 1-channel 16-bit")])
def test_mixed_sizes_and_depths_are_found_from_the_headers(tmp_path, no_pixels, second, found):
    png_header(tmp_path / "000.png", 64, 48)
    png_header(tmp_path / "001.png", second[0], second[1], bits=second[2])
    with pytest.raises(FileFormatError, match=f"001.png: image is {found}, but 000.png is 64x48 1-channel 8-bit"):
        read_stack([tmp_path / "000.png", tmp_path / "001.png"])


def test_the_budget_boundary_is_exact(tmp_path, budget):
    paths = []
    for k in range(3):
        paths.append(tmp_path / f"{k}.png")
        cv2.imwrite(str(paths[-1]), np.full((10, 10), k, np.uint8))
    budget("500")  # 3 images of 100 bytes + 2 working copies of the largest
    images = read_stack(paths)
    assert [int(im[0, 0]) for im in images] == [0, 1, 2] and images[0].shape == (10, 10)
    budget("499")
    with pytest.raises(BudgetError, match="needs 500 B .* budget of 499 B"):
        read_stack(paths)


def _tof_folder(folder, *, pulsed: bool = False):
    from rangekit.sim.sensors.tof import KINECT_V2_PLAN, tof_camera

    folder.mkdir()
    save_rig(Rig(cameras=(tof_camera(320, 240),)), folder / "rig.json")
    kind = "rangekit.tof.pulsed/1" if pulsed else "rangekit.tof.cw/1"
    (folder / "tof.json").write_text(json.dumps({"kind": kind, "plan": KINECT_V2_PLAN.to_dict()}))
    if not pulsed:
        (folder / "samples").mkdir()
    return folder


def test_huge_tof_samples_are_refused_before_loading(cli, tmp_path, budget, no_pixels):
    folder = _tof_folder(tmp_path / "raw")
    for k in range(9):
        png_header(folder / "samples" / f"{k:03d}.png", BIG, BIG, bits=16)
    run = cli("tof", folder, "--out", tmp_path / "out")
    assert_error(run, 1, "ToF raw samples", f"9 image(s) of {BIG}x{BIG} 1-channel 16-bit", "budget")
    assert not (tmp_path / "out").exists()


def test_tof_samples_of_another_size_than_the_camera_are_refused_from_the_headers(tmp_path, no_pixels):
    folder = _tof_folder(tmp_path / "raw")
    for k in range(9):
        png_header(folder / "samples" / f"{k:03d}.png", 64, 48, bits=16)
    with pytest.raises(FileFormatError, match="000.png: samples are 64x48 .* camera in rig.json is 320x240"):
        load_tof_folder(folder)


def test_a_pulsed_round_trip_file_with_a_huge_header_is_refused_before_allocating(tmp_path):
    folder = _tof_folder(tmp_path / "raw", pulsed=True)
    buf = io.BytesIO()
    np.lib.format.write_array_header_1_0(buf, {"descr": "<f8", "fortran_order": False, "shape": (200000, 200000)})
    (folder / "round_trip_s.npy").write_bytes(buf.getvalue() + b"\0" * 64)
    with pytest.raises(FileFormatError, match=r"round_trip_s.npy: shape \(200000, 200000\) but the camera .* 320x240"):
        load_tof_folder(folder)


def test_a_huge_stereo_pair_is_refused_from_the_headers(cli, tmp_path, budget, no_pixels):
    cam = template_rig()["cameras"][0]
    right = dict(cam, name="right", T_world_cam=[[1, 0, 0, 0.075], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])  # 75 mm
    (tmp_path / "rig.json").write_text(json.dumps({**template_rig(), "cameras": [cam, right]}))
    for name in ("l.png", "r.png"):
        png_header(tmp_path / name, BIG, BIG, colour=2)
    run = cli("stereo", tmp_path / "l.png", tmp_path / "r.png", "--rig", tmp_path / "rig.json", "--out", tmp_path / "o")
    assert_error(run, 1, "stereo pair", f"2 image(s) of {BIG}x{BIG} 3-channel 8-bit", "budget")
    assert not (tmp_path / "o").exists()


def test_huge_diligent_images_are_refused_before_loading(tmp_path, budget, no_pixels):
    from rangekit.photometric.diligent import load_diligent

    folder = tmp_path / "ballPNG"
    folder.mkdir()
    names = [f"{k:03d}.png" for k in range(1, 21)]
    (folder / "filenames.txt").write_text("\n".join(names) + "\n")
    (folder / "light_directions.txt").write_text("0 0 1\n" * 20)
    (folder / "light_intensities.txt").write_text("1 1 1\n" * 20)
    for n in names:
        png_header(folder / n, BIG, BIG, bits=16, colour=2)
    with pytest.raises(BudgetError, match=f"DiLiGenT images .*20 image\\(s\\) of {BIG}x{BIG} 3-channel 16-bit"):
        load_diligent(folder)


def test_header_checks_of_an_unknown_format_defer_to_opencv(tmp_path):
    ok, jpg = cv2.imencode(".jpg", np.full((6, 9), 7, np.uint8))
    (tmp_path / "a.png").write_bytes(jpg.tobytes())  # a JPEG named .png: no header known here
    assert check_image_files([tmp_path / "a.png"]) == [None]
    assert read_png(tmp_path / "a.png").shape == (6, 9)
