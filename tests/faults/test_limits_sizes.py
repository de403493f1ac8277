"""Nothing hangs or eats the machine: sizes checked before anything is allocated (pattern specs,
boards, rig cameras, voxels, render and simulator sizes, ToF plans). Each refusal names the input, what was
expected and what was found; options exit 2, file contents exit 1, and no output is written. (The memory
budget and image headers: test_limits.py.)"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from support.cli_runs import assert_error
from rangekit.boards import MAX_SQUARES, Board
from rangekit.camera import PinholeCamera
from rangekit.coded.patterns import PatternSpec
from rangekit.errors import BudgetError, ConfigError, InputError, PatternError, SceneError
from rangekit.rig.rig_file import load_rig, template_rig
from rangekit.surface.cloud import PointCloud, voxel_downsample


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
    from rangekit.sim.scene.objects import make_object

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
    with pytest.raises(InputError, match="voxel: expected a"):
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
    from rangekit.rendering.snapshot import raycast_mesh
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
