"""Data faults of the range commands (``tof``, ``stereo``, ``decode``, ``reconstruct``): each ends in one
``rangekit: error:`` line naming the file or folder with the expected and the found value, and writes
nothing; never a traceback, and never a result built from impossible data (a pulsed capture with negative
round trips gave 76,800 points at -1.5e8 m)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from support.cli_runs import assert_error


def _sim(tmp_path_factory, name: str, *args) -> Path:
    from rangekit.cli import main

    out = tmp_path_factory.mktemp("sim") / name
    assert main(["sim", "render", *args, "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def pulsed_src(tmp_path_factory):
    return _sim(tmp_path_factory, "pulsed", "--sensor", "tof-pulsed", "--size", "32x24")


@pytest.fixture(scope="module")
def cw_src(tmp_path_factory):
    return _sim(tmp_path_factory, "cw", "--sensor", "tof", "--size", "32x24")


@pytest.fixture(scope="module")
def stereo_src(tmp_path_factory):
    return _sim(tmp_path_factory, "stereo", "--sensor", "stereo", "--size", "64x48")


def _copy(src: Path, tmp_path: Path) -> Path:
    return Path(shutil.copytree(src, tmp_path / src.name))


def _edit_json(path: Path, edit) -> None:
    data = json.loads(path.read_text())
    edit(data)  # in place
    path.write_text(json.dumps(data))


# --------------------------------------------------------------------------------------------- ToF

def _round_trips(edit):
    def apply(folder: Path):
        path = folder / "round_trip_s.npy"
        np.save(path, edit(np.load(path)))
    return apply


def _negate_rows(dt):
    dt = dt.copy()
    dt[:3] = -np.abs(dt[:3])
    return dt


PULSED = {
    "all_negative": (_round_trips(lambda dt: np.full_like(dt, -1e-8)), "round_trip_s.npy",
                     ["768 of 768 pixels have negative round-trip times", "expected times in [0, 0.0001] s"]),
    "some_negative": (_round_trips(_negate_rows), "round_trip_s.npy", ["96 of 768 pixels have negative"]),
    "infinite": (_round_trips(lambda dt: np.where(np.arange(dt.size).reshape(dt.shape) == 5, np.inf, dt)),
                 "round_trip_s.npy", ["1 of 768 pixels have infinite"]),
    "seconds_as_nanoseconds": (_round_trips(lambda dt: dt * 1e9), "round_trip_s.npy", ["too long"]),
    "integers": (_round_trips(lambda dt: np.zeros(dt.shape, np.int64)), "round_trip_s.npy",
                 ["expected floating-point round-trip times", "int64"]),
    "wrong_shape": (_round_trips(lambda dt: dt[:5, :5]), "round_trip_s.npy",
                    ["shape (5, 5) but the camera in rig.json is 32x24"]),
    "not_npy": (lambda f: (f / "round_trip_s.npy").write_bytes(b"\x93NUMPY garbage"), "round_trip_s.npy",
                ["cannot read the round-trip times"]),
    "tof_json_list": (lambda f: (f / "tof.json").write_text("[1, 2]"), "tof.json",
                      ["expected a JSON object with 'kind', found a list"]),
    "tof_json_no_kind": (lambda f: (f / "tof.json").write_text("{}"), "tof.json", ["'kind' must be one of"]),
    "ground_truth_damaged": (lambda f: (f / "ground_truth.npz").write_bytes(b"PK\x03\x04 not a zip"),
                             "ground_truth.npz", ["cannot read the ground truth"]),
    "ground_truth_wrong_shape": (lambda f: np.savez(f / "ground_truth.npz", range=np.zeros((3, 3))),
                                 "ground_truth.npz", ["map 'range' is float64 (3, 3), expected float (24, 32)"]),
}


@pytest.mark.parametrize("name", list(PULSED))
def test_a_bad_pulsed_capture_is_a_clear_error(cli, pulsed_src, tmp_path, name):
    breakage, culprit, mentions = PULSED[name]
    folder = _copy(pulsed_src, tmp_path)
    breakage(folder)
    assert_error(cli("tof", folder, "--out", tmp_path / "out"), 1, f"{folder}/{culprit}", *mentions)
    assert not (tmp_path / "out").exists()


def test_the_pulsed_capture_decodes(cli, pulsed_src, tmp_path):
    run = cli("tof", pulsed_src, "--out", tmp_path / "out")
    assert run.code == 0, run.err
    rng = np.load(tmp_path / "out" / "range.npy")
    assert np.nanmin(rng) > 0.4 and np.nanmax(rng) < 16  # panels 0.5 to 15 m


def test_pulsed_range_refuses_negative_times():
    from rangekit.errors import InputError
    from rangekit.tof import pulsed_range

    assert pulsed_range(np.array([np.nan, 2e-9]))[1] == pytest.approx(0.299792458)
    with pytest.raises(InputError, match="1 of 2 pixels have negative round-trip times"):
        pulsed_range(np.array([-1e-9, 2e-9]))


def _samples(edit):
    def apply(folder: Path):
        for p in sorted((folder / "samples").iterdir()):
            edit(p)
    return apply


CW = {
    "gain_text": (lambda f: _edit_json(f / "tof.json", lambda m: m.update(electrons_per_dn="abc")), "tof.json",
                  ["'electrons_per_dn' must be a finite number > 0", '"abc"']),
    "gain_nan": (lambda f: _edit_json(f / "tof.json", lambda m: m.update(electrons_per_dn=float("nan"))),
                 "tof.json", ["'electrons_per_dn'", "NaN"]),
    "read_noise_list": (lambda f: _edit_json(f / "tof.json", lambda m: m.update(read_noise_e=[1])), "tof.json",
                        ["'read_noise_e' must be a finite number >= 0", "[1]"]),
    "saturation_negative": (lambda f: _edit_json(f / "tof.json", lambda m: m.update(saturation_dn=-5)),
                            "tof.json", ["'saturation_dn' must be a finite number > 0", "-5"]),
    "plan_missing": (lambda f: _edit_json(f / "tof.json", lambda m: m.pop("plan")), "tof.json",
                     ["plan: expected an object with 'frequencies_hz' and 'steps_rad'"]),
    "rgb_samples": (_samples(lambda p: cv2.imwrite(str(p), np.zeros((24, 32, 3), np.uint16))), "samples",
                    ["expected single-channel (grey) raw samples", "(24, 32, 3)"]),
    "samples_wrong_size": (_samples(lambda p: cv2.imwrite(str(p), np.zeros((20, 32), np.uint16))), "samples",
                           ["samples are 32x20 (width x height) but the camera in rig.json is 32x24"]),
    "one_sample_8_bit": (lambda f: cv2.imwrite(str(f / "samples" / "000.png"), np.zeros((24, 32), np.uint8)),
                         "samples/001.png", ["image is 32x24 1-channel 16-bit, but 000.png is 32x24 1-channel 8-bit"]),
    "sample_missing": (lambda f: (f / "samples" / "003.png").unlink(), "samples", ["needs 9 raw samples, found 8"]),
}


@pytest.mark.parametrize("name", list(CW))
def test_a_bad_continuous_wave_capture_is_a_clear_error(cli, cw_src, tmp_path, name):
    breakage, culprit, mentions = CW[name]
    folder = _copy(cw_src, tmp_path)
    breakage(folder)
    assert_error(cli("tof", folder, "--out", tmp_path / "out"), 1, f"{folder}/{culprit}", *mentions)
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------------------------------------------ stereo

def _camera_field(index, edit):
    return lambda f: _edit_json(f / "rig.json", lambda r: edit(r["cameras"][index]))


def _set_K(index, row, col, value):
    def edit(cam):
        cam["K"][row][col] = value
    return _camera_field(index, edit)


def _tiny_baseline(rig: dict) -> None:
    T = np.array(rig["cameras"][0]["T_world_cam"])
    T[0, 3] += 1e-12
    rig["cameras"][1]["T_world_cam"] = T.tolist()


STEREO = {
    "left_unreadable": (lambda f: (f / "left.png").write_bytes(b"\x89PNG\r\n"), "left.png",
                        ["not a readable image"]),
    "right_missing": (lambda f: (f / "right.png").unlink(), "right.png", ["not found; expected an image file"]),
    "left_is_a_folder": (lambda f: ((f / "left.png").unlink(), (f / "left.png").mkdir()), "left.png",
                         ["is a folder; expected an image file"]),
    "sizes_differ": (lambda f: cv2.imwrite(str(f / "right.png"), np.zeros((40, 64), np.uint8)), "right.png",
                     ["is 64x40", "a stereo pair needs two images of one size"]),
    "camera_size": (lambda f: [cv2.imwrite(str(f / n), np.zeros((40, 60), np.uint8)) for n in ("left.png", "right.png")],
                    "left.png", ["is 60x40 but the left camera 'left'", "is 64x48"]),
    "focal_nan": (_set_K(0, 0, 0, float("nan")), "rig.json", ["cameras[0].K", "finite numbers", "nan"]),
    "focal_zero": (_set_K(1, 0, 0, 0.0), "rig.json", ["cameras[1].K", "fx, fy > 0"]),
    "focal_negative": (_set_K(1, 1, 1, -44.0), "rig.json", ["cameras[1].K", "fx, fy > 0"]),
    "identical_cameras": (lambda f: _edit_json(f / "rig.json", lambda r: r["cameras"].__setitem__(
        1, dict(r["cameras"][0], name="right"))), "rig.json", ["is (0, 0, 0) m from", "a zero stereo baseline"]),
    "tiny_baseline": (lambda f: _edit_json(f / "rig.json", _tiny_baseline), "rig.json",
                      ["is (1e-12, 0, 0) m from", "a 1e-09 mm stereo baseline"]),
    "one_camera": (lambda f: _edit_json(f / "rig.json", lambda r: r["cameras"].pop()), "rig.json",
                   ["needs two cameras", "found 1"]),
}


@pytest.mark.parametrize("name", list(STEREO))
def test_a_bad_stereo_pair_or_rig_is_a_clear_error(cli, stereo_src, tmp_path, name):
    breakage, culprit, mentions = STEREO[name]
    folder = _copy(stereo_src, tmp_path)
    breakage(folder)
    run = cli("stereo", folder / "left.png", folder / "right.png", "--rig", folder / "rig.json",
              "--out", tmp_path / "out")
    assert_error(run, 1, f"{folder}/{culprit}", *mentions)
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------------------------------ decode, reconstruct

PROJ = (64, 40)


@pytest.fixture(scope="module")
def capture_src(tmp_path_factory) -> Path:
    """A graycode capture of a 64x40 projector seen by a 64x40 camera pixel for pixel (decodes exactly)."""
    from rangekit.coded.patterns import make_pattern_spec
    from rangekit.io import atomic_write_json, write_png
    from rangekit.rig.rig_file import template_rig

    folder = tmp_path_factory.mktemp("cap") / "capture"
    rig = template_rig()
    for dev in (rig["cameras"][0], rig["projector"]):
        dev["width"], dev["height"] = PROJ
        dev["K"] = (np.array(dev["K"]) * [[0.05], [0.05], [1]]).tolist()
        dev["K"][0][2], dev["K"][1][2] = (PROJ[0] - 1) / 2, (PROJ[1] - 1) / 2
    atomic_write_json(folder / "rig.json", rig)
    spec = make_pattern_spec("graycode", PROJ)
    atomic_write_json(folder / "patterns.json", spec.to_dict())
    for i, frame in enumerate(spec.frames()):
        write_png(folder / f"{i:03d}.png", np.asarray(frame, np.uint8))
    return folder


def _fill_all(value, dtype=np.uint8):
    def apply(folder: Path):
        for p in folder.glob("*.png"):
            cv2.imwrite(str(p), np.full((PROJ[1], PROJ[0]), value, dtype))
    return apply


def _drop_frames(folder: Path):
    for p in sorted(folder.glob("*.png"))[10:]:
        p.unlink()


def _no_projector(folder: Path):
    _edit_json(folder / "rig.json", lambda r: r.pop("projector"))


def _float_nan(folder: Path):
    for p in folder.glob("*.png"):
        img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED).astype(np.float32)
        img[3:10, 3:10] = np.nan
        cv2.imwrite(str(p.with_suffix(".tiff")), img)
        p.unlink()


CAPTURES = {
    "all_black": (_fill_all(0), ["no pixel is lit"]),
    "all_white": (_fill_all(255), ["no pixel is lit"]),
    "all_white_16_bit": (_fill_all(65535, np.uint16), ["no pixel is lit"]),
    "fewer_images_than_patterns": (_drop_frames, ["found 10 captures", "needs 26"]),
    "patterns_json_frames": (lambda f: _edit_json(f / "patterns.json", lambda s: s.update(frames=["white"])),
                             ["patterns.json", "frame list (1 frames) does not match", "(26 frames)"]),
    "float_images_with_nan": (_float_nan, ["float32", "expected uint8 or uint16"]),
    "one_image_16_bit": (lambda f: cv2.imwrite(str(f / "005.png"), np.zeros((40, 64), np.uint16)),
                         ["005.png", "image is 64x40 1-channel 16-bit, but 000.png is 64x40 1-channel 8-bit"]),
}


@pytest.mark.parametrize("command", ["decode", "reconstruct"])
@pytest.mark.parametrize("name", list(CAPTURES))
def test_a_bad_capture_is_a_clear_error(cli, capture_src, tmp_path, command, name):
    breakage, mentions = CAPTURES[name]
    folder = _copy(capture_src, tmp_path)
    breakage(folder)
    out = tmp_path / ("maps.npz" if command == "decode" else "cloud.ply")
    args = ["--pattern", folder / "patterns.json"] if command == "decode" else []
    assert_error(cli(command, folder, *args, "--out", out), 1, str(folder), *mentions)
    assert not out.exists()


@pytest.mark.parametrize("edit, mentions", [
    (_no_projector, ["no rig.json with a projector"]),
    (lambda f: _edit_json(f / "rig.json", lambda r: r.update(projector=None)), ["no rig.json with a projector"]),
    (lambda f: _edit_json(f / "rig.json", lambda r: r["cameras"][0].update(width=128)),
     ["captures are 64x40", "camera 'camera' is 128x40"]),
    (lambda f: _edit_json(f / "rig.json", lambda r: r["projector"].update(width=128)),
     ["pattern spec is for a 64x40 projector", "projector is 128x40"]),
], ids=["no_projector", "projector_null", "camera_size", "projector_size"])
def test_reconstruct_with_a_rig_that_does_not_fit(cli, capture_src, tmp_path, edit, mentions):
    folder = _copy(capture_src, tmp_path)
    edit(folder)
    assert_error(cli("reconstruct", folder, "--out", tmp_path / "c.ply"), 1, str(folder), *mentions)
    assert not (tmp_path / "c.ply").exists()


def test_the_capture_decodes_exactly(cli, capture_src, tmp_path):
    run = cli("decode", capture_src, "--pattern", capture_src / "patterns.json", "--integer",
              "--out", tmp_path / "maps.npz")
    assert run.code == 0, run.err
    with np.load(tmp_path / "maps.npz") as maps:
        cols = maps["proj_col"]
    assert np.array_equal(cols[5], np.arange(PROJ[0]))
