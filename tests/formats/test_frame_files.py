"""A tool's capture under any file names (issue 47 item 5): frames in numeric order of their names when the tool's
names are absent, from a folder, a glob or the shell's expansion of one, each camera said in one line; counts
that are not the layout's refused in one line.

Conditions: the default rig's camera at 640x512 and its projector at 1100x688 (as tests/formats/
test_layout_presets.py), SLStudio's 12-frame Gray code (``frameSeq_00..11``), written as ``1.png ... 12.png`` and
``scan_01.png ... scan_12.png``; the decoded columns against the simulator's true projector column over the
object's lit interior.
"""

from __future__ import annotations

import shutil
from dataclasses import replace

import cv2
import numpy as np
import pytest
from scipy.ndimage import binary_erosion

from support.cli_runs import assert_error
from rangekit.coded.decode import decode
from rangekit.errors import ConfigError, DecodeError, FileFormatError
from rangekit.formats.capture import read_stack
from rangekit.formats.layouts import LAYOUTS, arrange, capture_frames, in_projector_pixels, tool_frames
from rangekit.rig.rig_file import save_rig
from rangekit.sim import ImagingModel, SimRig, default_rig, default_scene

PROJECTOR = (1100, 688)
LAYOUT = LAYOUTS["slstudio:graycode"]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """(folder of 1.png ... 12.png, folder of scan_01.png ... scan_12.png, the rig file, the truth)."""
    r = default_rig()
    rig = replace(r, cameras=(r.camera.resized(640, 512),), projector=r.projector.resized(*PROJECTOR))
    sim = SimRig(default_scene(), rig, imaging=ImagingModel(), seed=3)
    root = tmp_path_factory.mktemp("any_names")
    plain, padded = root / "plain", root / "padded"
    plain.mkdir(), padded.mkdir()
    for k, image in enumerate(sim.capture_sequence(tool_frames(LAYOUT, *PROJECTOR))):
        assert cv2.imwrite(str(plain / f"{k + 1}.png"), image)
        assert cv2.imwrite(str(padded / f"scan_{k + 1:02d}.png"), image)
    save_rig(rig, root / "rig.json")
    return plain, padded, root / "rig.json", sim.ground_truth()


def _column_errors(files, truth):
    """(RMS of the decoded column's errors within 2 px, share of gross errors) over the lit interior."""
    stack, spec = arrange(list(read_stack(files)), LAYOUT, *PROJECTOR)
    dec = in_projector_pixels(decode(stack, spec, **LAYOUT.view_options.get("decode_options", {})), LAYOUT,
                              *PROJECTOR)
    e = (dec.proj_col - truth.proj_col)[binary_erosion(truth.lit, iterations=3)]
    e = e[np.isfinite(e)]
    good = np.abs(e) <= 2
    return float(np.sqrt(np.mean(e[good] ** 2))), float(1 - good.mean())


def test_frames_of_any_names_are_taken_in_numeric_order(recorded):
    """Both folders, a quoted glob, and the shell's expansion of the glob (lexicographic: 1, 10, 11, 12, 2, ...)
    give the frames 1 ... 12 in numeric order, and decode to the true columns as under the tool's own names
    (test_layout_presets: 0.071 px, gross < 0.05%); the same files in the shell's order decode to codes off the
    projector and are refused."""
    plain, padded, _, truth = recorded
    numeric = [plain / f"{k}.png" for k in range(1, 13)]
    shell = sorted(numeric, key=str)
    assert [p.name for p in shell[:5]] == ["1.png", "10.png", "11.png", "12.png", "2.png"]
    for given, where in (([plain], str(plain)), ([str(plain / "*.png")], str(plain / "*.png")),
                         (shell, str(plain))):
        (found,) = capture_frames(given, LAYOUT, *PROJECTOR)
        assert list(found.files) == numeric
        assert found.line() == f"camera 1: 12 frames 1.png ... 12.png (numeric order of the names) from {where}"
    (found,) = capture_frames([padded], LAYOUT, *PROJECTOR)
    assert [p.name for p in found.files] == [f"scan_{k:02d}.png" for k in range(1, 13)]
    rms, gross = _column_errors(found.files, truth)
    print(f"\nany names, numeric order: column RMS {rms:.3f} px, gross {gross:.4f}")
    assert rms <= 0.1 and gross <= 0.0005
    rms, gross = _column_errors(numeric, truth)
    assert rms <= 0.1 and gross <= 0.0005
    with pytest.raises(DecodeError, match="codes outside"):             # the order matters: the test can fail
        _column_errors(shell, truth)


def test_reconstruct_says_which_files_it_took(cli, recorded, tmp_path):
    plain, _, rig, _ = recorded
    run = cli("reconstruct", plain, "--pattern", "slstudio:graycode", "--rig", rig, "--out", tmp_path / "c.ply")
    assert run.code == 0, run.err
    assert f"camera 1: 12 frames 1.png ... 12.png (numeric order of the names) from {plain}" in run.out
    run = cli("decode", plain / "*.png", "--pattern", "slstudio:graycode", "--projector", "1100x688",
              "--out", tmp_path / "maps.npz")
    assert run.code == 0, run.err
    assert "(numeric order of the names) from " in run.out


def test_a_count_that_is_not_the_layouts_is_one_line(cli, recorded, tmp_path):
    """A folder, a glob or files of another count than the layout's, a glob matching nothing, one folder of any
    names for a rig of two cameras: each refused in one line naming where, the expected and the found; a folder
    holding some of the tool's names is read by them (the first missing named), never by numeric order."""
    plain, _, rig, _ = recorded
    short = tmp_path / "short"
    shutil.copytree(plain, short)
    (short / "12.png").unlink()
    with pytest.raises(FileFormatError, match=r"short: expected the 12 frames of slstudio:graycode for a 1100x688 "
                                              r"projector \(frameSeq_00.bmp ... frameSeq_11.bmp, or 12 image files of "
                                              r"any names, taken in numeric order\), found 11 image files"):
        capture_frames([short], LAYOUT, *PROJECTOR)
    with pytest.raises(FileFormatError, match=r"short/\*.png: expected the 12 frames .*, found 11 image files"):
        capture_frames([str(short / "*.png")], LAYOUT, *PROJECTOR)
    with pytest.raises(FileFormatError, match=r"nothing/\*.png: expected image files .* found none"):
        capture_frames([str(tmp_path / "nothing" / "*.png")], LAYOUT, *PROJECTOR)
    with pytest.raises(ConfigError, match=r"expected two cameras' captures \(a folder or glob per camera\), found "
                                          "one camera's"):
        capture_frames([plain], LAYOUT, *PROJECTOR, cameras=2)
    with pytest.raises(ConfigError, match="expected the captures of 1 camera"):
        capture_frames([plain, short], LAYOUT, *PROJECTOR)
    shutil.copy(plain / "1.png", short / "frameSeq_00.bmp")
    with pytest.raises(FileFormatError, match="frameSeq_01.bmp missing and 10 more"):
        capture_frames([short], LAYOUT, *PROJECTOR)
    run = cli("reconstruct", *sorted(short.glob("*.png"))[:5], "--pattern", "slstudio:graycode", "--rig", rig,
              "--out", tmp_path / "c.ply")
    assert_error(run, 1, str(short), "expected the 12 frames of slstudio:graycode", "found 5 image files")
    assert not (tmp_path / "c.ply").exists()
