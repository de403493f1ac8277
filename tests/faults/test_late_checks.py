"""Sizes and outputs checked early and named (issue 34, "late or unnamed size checks" and "other silent
acceptance"): a PLY header that declares more than its body holds, standard output that cannot be written,
an over-long or folder-like --out, an empty --out, a turntable step out of range, a textured OBJ without
Pillow, and rig imports whose values are text or nested without end."""

from __future__ import annotations

import os
import struct
import subprocess
import sys

import numpy as np
import pytest

from support.cli_runs import ROOT, assert_error


def _ply_declaring(path, faces: int, binary: bool = True) -> None:
    head = ("ply\nformat " + ("binary_little_endian" if binary else "ascii") + " 1.0\nelement vertex 3\n"
            "property float x\nproperty float y\nproperty float z\n"
            f"element face {faces}\nproperty list uchar int vertex_indices\nend_header\n").encode()
    body = (struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0) + struct.pack("<B3i", 3, 0, 1, 2) if binary else
            b"0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n")
    path.write_bytes(head + body)


@pytest.mark.parametrize("faces", [300_000_000, 4_000_000_000])
@pytest.mark.parametrize("command", ["render", "mesh", "register"])
def test_a_ply_declaring_more_faces_than_it_holds_is_refused_from_its_size(cli, tmp_path, faces, command):
    """3e8 faces took 33 s and 2.5 GB before the refusal, 4e9 ended in an unnamed 'out of memory'."""
    src = tmp_path / "huge.ply"
    _ply_declaring(src, faces)
    args = {"render": [src, "--out", tmp_path / "h.png"], "mesh": [src, "--out", tmp_path / "m.ply"],
            "register": [src, src, "--no-mesh", "--out", tmp_path / "r"]}[command]
    run = cli(command, *args)
    assert_error(run, 1, str(src), f"header declares {faces} faces", "ends after 1")


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full")
def test_standard_output_that_cannot_be_written_is_named():
    with open("/dev/full", "w") as full:
        proc = subprocess.run([sys.executable, "-m", "rangekit", "sim", "objects"], stdout=full, stderr=subprocess.PIPE,
                              stdin=subprocess.DEVNULL, text=True, timeout=120,
                              env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr.strip().splitlines()[-1] == ("rangekit: error: standard output: cannot be written (No space "
                                                    "left on device); send it to a file or a pipe that takes it")


@pytest.fixture
def points(tmp_path):
    src = tmp_path / "pts.xyz"
    np.savetxt(src, np.random.default_rng(0).normal(size=(300, 3)) * 0.05)
    return src


@pytest.mark.parametrize("out, words", [
    ("{tmp}/m.ply/", ["ends with '/'", "expected a file name"]),
    ("{tmp}/" + "a" * 300 + ".ply", ["longer than the system allows"]),
    ("", ["--out: an empty path"]),
])
def test_a_mesh_output_that_cannot_be_a_file_is_a_usage_error(cli, tmp_path, points, out, words):
    run = cli("mesh", points, "--out", out.format(tmp=tmp_path))
    assert_error(run, 2, *words)
    assert not (tmp_path / "m.ply").exists()


@pytest.mark.parametrize("flag", ["--out", "--resume"])
def test_an_empty_scan_folder_is_a_usage_error(cli, tmp_path, flag, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "keep.txt").write_text("the working folder is not a session")
    run = cli("scan", flag, "")
    assert_error(run, 2, f"{flag}: an empty path")


@pytest.mark.parametrize("step", ["1e308", "1e400", "inf", "nan", "361", "-720"])
def test_a_turntable_step_out_of_range_is_a_usage_error(cli, tmp_path, points, step):
    run = cli("register", points, points, "--init", f"turntable:0,0,1:{step}", "--out", tmp_path / "r")
    assert_error(run, 2, "--init", "at most 360 degrees")


def test_an_obj_with_texture_coordinates_reads_without_pillow(cli, tmp_path):
    src = tmp_path / "t.obj"
    src.write_text("v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0 0 0.1\nvt 0 0\nvt 1 0\nvt 0 1\n"
                   "f 1/1 2/2 3/3\nf 1/1 2/2 4/3\nf 1/1 3/2 4/3\nf 2/1 3/2 4/3\n")
    from rangekit.formats.meshes import load_mesh

    mesh = load_mesh(src)
    assert mesh.triangles.shape == (4, 3) and np.allclose(mesh.vertices.max(axis=0), 0.1)
    run = cli("render", src, "--out", tmp_path / "t.png")
    assert run.code == 0, run.err


@pytest.mark.parametrize("text, words", [
    ("%YAML:1.0\n---\nK1: \"hello\"\n", ["K1: expected a matrix or numbers, found the text 'hello'"]),
    ("%YAML:1.0\n---\nK1: [1, \"a\", 3]\n", ["K1: expected a sequence of numbers"]),
    ("%YAML:1.0\n---\nK1: [1, 2\n", ["cannot read"]),
])
def test_an_opencv_calibration_with_text_for_numbers_or_cut_short_is_named(cli, tmp_path, text, words):
    src = tmp_path / "calib.yaml"
    src.write_text(text)
    run = cli("rig", "import", src, "--out", tmp_path / "rig.json")
    assert_error(run, 1, str(src), *words)
    assert not (tmp_path / "rig.json").exists()


def test_a_calibration_json_nested_without_end_is_named(cli, tmp_path):
    src = tmp_path / "deep.json"
    src.write_text("[" * 100_000 + "]" * 100_000)
    run = cli("rig", "import", src, "--out", tmp_path / "rig.json")
    assert_error(run, 1, str(src), "nested too deeply")


def test_a_1_bit_frame_among_8_bit_frames_is_refused_from_the_headers(cli, tmp_path):
    """A 1-bit PNG decodes to 0/255, a binarised frame: it used to decode to fewer points without a word."""
    import cv2

    rng = np.random.default_rng(0)
    for k in range(4):
        cv2.imwrite(str(tmp_path / f"{k:03d}.png"), rng.integers(0, 256, (32, 64), dtype=np.uint8))
    cv2.imwrite(str(tmp_path / "002.png"), (rng.random((32, 64)) > 0.5).astype(np.uint8) * 255,
                [cv2.IMWRITE_PNG_BILEVEL, 1])
    run = cli("decode", tmp_path, "--pattern", "graycode", "--projector", "64x32", "--out", tmp_path / "m.npz")
    assert_error(run, 1, "002.png", "1-bit in the file", "000.png is 64x32 1-channel 8-bit", "one size and depth")


def test_resume_flipped_on_a_one_pass_session_is_a_usage_error(cli, tmp_session):
    run = cli("scan", "--resume", tmp_session, "--flipped", "--no-process")
    assert_error(run, 2, "--flipped", "has one pass", "leave --flipped out")
