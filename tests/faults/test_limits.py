"""Nothing hangs or eats the machine (issue 16): the memory budget, image headers read before any pixel, and
sizes checked before anything is allocated (pattern specs, boards, rig cameras, voxels, render and simulator
sizes, ToF plans). Each refusal names the input, what was expected and what was found; options exit 2,
file contents exit 1, and no output is written."""

from __future__ import annotations

import io
import json
import struct
import zlib

import cv2
import numpy as np
import pytest

from _faults import assert_error
from rangekit.boards import MAX_SQUARES, Board
from rangekit.budget import (ENV_VAR, array_bytes, cgroup_memory_limit, check_budget, format_bytes, memory_budget,
                             parse_bytes, physical_memory)
from rangekit.camera import PinholeCamera
from rangekit.coded.patterns import PatternSpec
from rangekit.errors import (BudgetError, BudgetUsageError, ConfigError, FileFormatError, InputError, PatternError,
                             SceneError, UsageError)
from rangekit.formats.capture import load_capture, read_stack
from rangekit.formats.range_files import load_tof_folder
from rangekit.image_header import check_image_files, read_image_header
from rangekit.io import read_png
from rangekit.rig import Rig, load_rig, save_rig, template_rig
from rangekit.surface.cloud import PointCloud, voxel_downsample

BIG = 20000  # pixels per side of the huge images the issue describes (44 of them: 7 GB and more)


# ----------------------------------------------------------------------------- helpers
def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_header(path, width: int, height: int, *, bits: int = 8, colour: int = 0) -> None:
    """A PNG cut after its IHDR chunk: the header of a ``width`` x ``height`` image, no pixels (33 bytes)."""
    ihdr = struct.pack(">IIBBBBB", width, height, bits, colour, 0, 0, 0)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr))


@pytest.fixture
def budget(monkeypatch):
    """Set the memory budget (RANGEKIT_MEMORY_BUDGET) for one test, independent of this machine's memory."""
    def set_budget(text: str) -> None:
        monkeypatch.setenv(ENV_VAR, text)
    set_budget("4G")
    return set_budget


@pytest.fixture
def no_pixels(monkeypatch):
    """Fail the test if any image is decoded (the refusals must come from the headers)."""
    def imread(*args, **kwargs):
        raise AssertionError(f"pixels were read: cv2.imread{args}")
    monkeypatch.setattr(cv2, "imread", imread)


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
    from rangekit.sim.tof import KINECT_V2_PLAN, tof_camera

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
    (tmp_path / "rig.json").write_text(json.dumps({**template_rig(), "cameras": [cam, dict(cam, name="right")]}))
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


# ----------------------------------------------------------------------------- pattern specs, boards, rigs
@pytest.mark.parametrize("options, method, mentions", [
    ({"steps": 1e8}, "phase", ["steps", "3..64", "100000000"]),
    ({"steps": float("inf")}, "hybrid", ["steps", "inf"]),
    ({"steps": -3}, "phase", ["steps", "-3"]),
    ({"steps": 4.5}, "phase", ["steps", "4.5"]),
    ({"steps": "4"}, "phase", ["steps", "'4'"]),
    ({"fine_steps": 10**9}, "phase", ["fine_steps", "1000000000"]),
    ({"n": 50}, "debruijn", ["n=50", "at most 1048576"]),
    ({"k": 7}, "debruijn", ["k", "2..6", "7"]),
    ({"stripe_width": 0}, "debruijn", ["stripe_width", "0"]),
    ({"periods": [64.0, 0.0]}, "phase", ["periods", "0.0"]),
    ({"periods": [64.0] + [1.0] * 20}, "phase", ["periods", "1 to 16"]),
    ({"period": float("nan")}, "hybrid", ["period", "nan"]),
    ([["steps", 4]], "phase", ["options", "object"]),
])
def test_absurd_pattern_options_are_refused_naming_the_file(options, method, mentions):
    with pytest.raises(PatternError) as err:
        PatternSpec.from_dict({"method": method, "width": 64, "height": 40, "options": options}, where="p.json")
    assert str(err.value).startswith("p.json: ")
    for m in mentions:
        assert m in str(err.value)


@pytest.mark.parametrize("width, height, found", [(10**9, 40, "1000000000"), (64, -5, "-5"), (12.5, 40, "12.5"),
                                                  (True, 40, "True"), (float("inf"), 40, "inf"), ("64", 40, "'64'")])
def test_absurd_pattern_sizes_are_refused(width, height, found):
    with pytest.raises(PatternError, match=f"p.json: pattern (width|height) .* 1..16384, found {found}"):
        PatternSpec.from_dict({"method": "graycode", "width": width, "height": height}, where="p.json")


def test_decode_with_an_absurd_pattern_file_exits_1_naming_it(cli, tmp_path):
    for k in range(2):
        cv2.imwrite(str(tmp_path / f"{k:03d}.png"), np.zeros((8, 8), np.uint8))
    spec = tmp_path / "p.json"
    spec.write_text(json.dumps({"method": "phase", "width": 64, "height": 40, "options": {"steps": 1e8}}))
    run = cli("decode", tmp_path / "000.png", tmp_path / "001.png", "--pattern", spec, "--out", tmp_path / "m.npz")
    assert_error(run, 1, str(spec), "steps", "100000000")
    assert not (tmp_path / "m.npz").exists()


def test_a_pattern_frame_over_the_budget_is_refused(budget):
    budget("1M")
    with pytest.raises(BudgetError, match="a 1700x1000 debruijn pattern frame needs 4.86 MiB"):
        PatternSpec(method="debruijn", width=1700, height=1000)


@pytest.mark.parametrize("cols, rows", [(1000, 1000), (MAX_SQUARES + 1, 7), (10, 10**9)])
def test_huge_boards_are_refused(cols, rows):
    with pytest.raises(InputError, match=f"must be an integer in 2..{MAX_SQUARES}"):
        Board(cols=cols, rows=rows)


def test_the_largest_board_is_accepted_and_its_fine_texture_checked_against_the_budget(budget):
    board = Board(cols=MAX_SQUARES, rows=MAX_SQUARES - 1)
    assert board.n_corners == 99 * 98
    with pytest.raises(BudgetError, match=r"texture of a 100x99 board \(202000x200000 texels"):
        board.texture(1e-5)


def test_a_huge_simulated_board_is_a_scene_error():
    from rangekit.sim.objects import make_object

    with pytest.raises(SceneError, match="board: .*cols .* 2..100, found 1000"):
        make_object("board", cols=1000, rows=1000)


@pytest.mark.parametrize("width", [10**9, 16385, 1e300])
def test_rig_cameras_larger_than_the_largest_image_are_refused(tmp_path, width):
    rig = template_rig()
    rig["cameras"][0]["width"] = width
    (tmp_path / "rig.json").write_text(json.dumps(rig))
    with pytest.raises(ConfigError, match=r"rig.json: cameras\[0\].width: .* at most 16384"):
        load_rig(tmp_path / "rig.json")


def test_simulating_a_rig_file_camera_over_the_budget_exits_1_naming_the_file(cli, tmp_path, budget):
    rig = template_rig()
    rig["cameras"][0].update(width=16384, height=16384)
    (tmp_path / "rig.json").write_text(json.dumps(rig))
    run = cli("sim", "render", "--rig", tmp_path / "rig.json", "--out", tmp_path / "cap")
    assert_error(run, 1, "rig.json", "16384x16384", "budget of 4 GiB")
    assert not (tmp_path / "cap").exists()


# ----------------------------------------------------------------------------- voxels
def _scans(tmp_path, n=2):
    rng = np.random.default_rng(0)
    paths = []
    for k in range(n):
        paths.append(tmp_path / f"s{k}.xyz")
        np.savetxt(paths[-1], rng.uniform(0.0, 0.1, (300, 3)))
    return paths


def test_register_with_an_absurdly_small_voxel_is_refused_before_any_work(cli, tmp_path):
    run = cli("register", *_scans(tmp_path), "--voxel-mm", "0.001", "--out", tmp_path / "r")
    line = assert_error(run, 2, "--voxel-mm 0.001", "expected a voxel of at least", "found 0.001 mm")
    assert "/ 2000" in line
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("voxel", [0.0, -0.003, float("nan"), float("inf"), 1e-9, "2mm"])
def test_register_views_refuses_bad_voxels(voxel):
    from rangekit.registration.multiview import MultiViewOptions, register_views

    rng = np.random.default_rng(1)
    clouds = [PointCloud(rng.uniform(0, 0.1, (100, 3))) for _ in range(2)]
    with pytest.raises(InputError, match="voxel: expected a voxel of at least"):
        register_views(clouds, options=MultiViewOptions(voxel=voxel))


def test_voxel_grids_that_would_overflow_are_refused_not_merged():
    P = np.array([[0.0, 0.0, 0.0], [1e6, 1e6, 1e6], [1e6, 0.0, 0.0]])
    with pytest.raises(InputError, match="more grid cells than 2\\*\\*62"):
        voxel_downsample(P, 1e-9)
    out, _ = voxel_downsample(np.array([[0.0, 0, 0], [0.1, 0, 0], [5.0, 0, 0]]), 1.0)
    assert out.tolist() == [[0.05, 0.0, 0.0], [5.0, 0.0, 0.0]]


# ----------------------------------------------------------------------------- render and simulator sizes
def test_render_size_over_the_budget_exits_2_before_reading_the_file(cli, tmp_path, budget):
    mesh = tmp_path / "m.obj"
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    run = cli("render", mesh, "--size", "16000x16000", "--out", tmp_path / "p.png")
    assert_error(run, 2, "--size 16000x16000", "rendering a mesh", "budget of 4 GiB")
    assert not (tmp_path / "p.png").exists()


def test_many_render_sides_count_against_the_budget(cli, tmp_path, budget):
    budget("100M")
    cloud = _scans(tmp_path, 1)[0]
    run = cli("render", cloud, "--size", "4000x4000", "--azimuth", *range(0, 360, 36), "--out", tmp_path / "p.png")
    assert_error(run, 2, "--size 4000x4000", "rendering a cloud from 10 side(s)", "budget of 100 MiB")


def test_ray_casting_checks_the_budget_in_the_library(budget):
    from rangekit.app.snapshot import raycast_mesh
    from rangekit.surface.mesh import TriangleMesh

    mesh = TriangleMesh(np.array([[0.0, 0, 1], [1, 0, 1], [0, 1, 1]]), np.array([[0, 1, 2]]))
    cam = PinholeCamera(K=np.array([[1e4, 0, 8e3], [0, 1e4, 8e3], [0, 0, 1]]), width=16000, height=16000)
    with pytest.raises(BudgetError, match="ray casting a 16000x16000 image"):
        raycast_mesh(mesh, cam)


@pytest.mark.parametrize("sensor", ["tof", "tof-pulsed", "stereo"])
def test_simulator_sensor_sizes_over_the_budget_exit_2(cli, tmp_path, budget, sensor):
    run = cli("sim", "render", "--sensor", sensor, "--size", "16000x16000", "--out", tmp_path / "cap")
    assert_error(run, 2, "--size 16000x16000", f"simulating a 16000x16000 {sensor} camera", "budget of 4 GiB")
    assert not (tmp_path / "cap").exists()


def test_too_many_tof_frequencies_exit_2(cli, tmp_path):
    run = cli("sim", "render", "--sensor", "tof", "--frequencies-mhz", *range(1, 41), "--out", tmp_path / "cap")
    assert_error(run, 2, "--frequencies-mhz", "at most 16 frequencies", "found 40")
    assert not (tmp_path / "cap").exists()


@pytest.mark.parametrize("plan", [
    {"frequencies_hz": [1e6 * (k + 1) for k in range(17)], "steps_rad": [[0, 2, 4]] * 17},
    {"frequencies_hz": [1e7], "steps_rad": [[0.01 * k for k in range(65)]]},
])
def test_tof_plans_in_files_are_bounded(plan):
    from rangekit.tof import FrequencyPlan

    with pytest.raises(InputError, match="at most 16 frequencies of at most 64 phase steps"):
        FrequencyPlan.from_dict(plan, where="tof.json: plan")


def test_header_checks_of_an_unknown_format_defer_to_opencv(tmp_path):
    ok, jpg = cv2.imencode(".jpg", np.full((6, 9), 7, np.uint8))
    (tmp_path / "a.png").write_bytes(jpg.tobytes())  # a JPEG named .png: no header known here
    assert check_image_files([tmp_path / "a.png"]) == [None]
    assert read_png(tmp_path / "a.png").shape == (6, 9)
