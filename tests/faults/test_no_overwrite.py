"""No command writes over a file it did not make in this run's output set, or over one of its own inputs,
unless told --force (issue 48): each refusal is one line naming the file and the option, before any work,
and nothing changes. rangekit.formats.output_sets.claim_folder for folders, rangekit.cli._common.check_output
for files."""

from __future__ import annotations

import pytest

from support.cli_runs import assert_error
from rangekit.errors import UsageError
from rangekit.formats.output_sets import claim_folder, file_owner

# Commands whose --out is one file (their inputs need not exist: the output is checked first).
FILE_OUTPUTS = [
    ["decode", "caps", "--pattern", "graycode", "--projector", "64x32"],
    ["reconstruct", "caps"],
    ["mesh", "cloud.ply"],
    ["render", "mesh.ply"],
    ["calibrate"],
    ["rig", "import", "calib.yml"],
]
SUFFIX = {"decode": "maps.npz", "reconstruct": "cloud.ply", "mesh": "mesh.ply", "render": "picture.png",
          "calibrate": "rig.json", "rig": "rig.json"}


def _tree(folder):
    return {p.relative_to(folder).as_posix(): (p.read_bytes() if p.is_file() else None)
            for p in sorted(folder.rglob("*"))}


@pytest.mark.parametrize("args", FILE_OUTPUTS, ids=lambda a: a[0])
def test_every_file_output_that_exists_needs_force(cli, tmp_path, args):
    out = tmp_path / SUFFIX[args[0]]
    out.write_text("mine")
    run = cli(*args, "--out", out)
    assert_error(run, 2, f"--out {out}", "exists", "--force")
    assert out.read_text() == "mine"


def test_sim_render_does_not_write_over_the_users_files(cli, tmp_path):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "rig.json").write_text("my rig")
    (out / "image.png").write_text("my picture")
    run = cli("sim", "render", "--sensor", "dots", "--size", "160x100", "--out", out)
    assert_error(run, 2, f"--out {out}", "image.png", "exists", "--force")
    assert _tree(out) == {"image.png": b"my picture", "rig.json": b"my rig"}
    # only what the sensor writes counts: a user's 000.png is no dots capture's file
    other = tmp_path / "other"
    other.mkdir()
    (other / "000.png").write_text("mine")
    run = cli("sim", "render", "--sensor", "dots", "--size", "160x100", "--out", other)
    assert run.code == 0, run.err
    assert (other / "000.png").read_text() == "mine"
    run = cli("sim", "render", "--sensor", "dots", "--size", "160x100", "--out", other)   # its own set: a rerun
    assert run.code == 0, run.err
    run = cli("sim", "render", "--sensor", "dots", "--size", "160x100", "--out", out, "--force")
    assert run.code == 0, run.err
    assert (out / "rig.json").read_text() != "my rig"


def test_sim_render_does_not_write_over_its_own_rig(cli, tmp_path, small_rig):
    from rangekit.rig.rig_file import save_rig

    out = tmp_path
    small_rig_file = out / "rig.json"
    save_rig(small_rig, small_rig_file)
    (out / "ground_truth.npz").write_bytes(b"an earlier capture")   # the folder holds a capture
    rig = small_rig_file.read_bytes()
    run = cli("sim", "render", "--rig", small_rig_file, "--out", out)
    assert_error(run, 2, f"--out {out}", "rig.json", "this command's input", "--force")
    assert small_rig_file.read_bytes() == rig


def test_a_calibration_does_not_replace_an_earlier_coverage_picture(cli, tmp_path):
    (tmp_path / "coverage.png").write_bytes(b"the last calibration's")
    run = cli("calibrate", "--captures", tmp_path / "a", tmp_path / "b", tmp_path / "c", "--pattern",
              "slstudio:calibration", "--projector", "64x32", "--out", tmp_path / "rig.json")
    assert_error(run, 2, "--out", "coverage.png", "exists", "--force")
    assert (tmp_path / "coverage.png").read_bytes() == b"the last calibration's"


def test_reconstruct_does_not_replace_a_sessions_mesh(cli, tmp_path):
    session = tmp_path / "S"
    session.mkdir()
    (session / "session.json").write_text("{}")
    (session / "mesh.ply").write_text("the session's mesh")
    run = cli("reconstruct", tmp_path / "caps", "--out", session / "mesh.ply")
    assert_error(run, 2, f"--out {session / 'mesh.ply'}", "belongs to a scan session", "session.json", "--force")
    assert (session / "mesh.ply").read_text() == "the session's mesh"


def test_reconstruct_checks_the_refined_rig_beside_its_cloud(cli, tmp_path):
    (tmp_path / "cloud.refined-rig.json").write_text("mine")
    run = cli("reconstruct", tmp_path / "caps", "--out", tmp_path / "cloud.ply")
    assert_error(run, 2, "--out", "cloud.refined-rig.json", "written beside it", "--force")


def test_register_does_not_write_over_its_own_input(cli, tmp_path):
    a = tmp_path / "a"
    a.mkdir()
    (a / "poses.json").write_text("{}")            # an earlier registration's set ...
    (a / "merged.ply").write_text("scan a")       # ... whose merged cloud is now an input
    (tmp_path / "b.ply").write_text("scan b")
    before = _tree(a)
    run = cli("register", a / "merged.ply", tmp_path / "b.ply", "--out", a)
    assert_error(run, 2, f"--out {a}", "merged.ply", "this command's input", "--force")
    assert _tree(a) == before
    # the same through another spelling of the path
    run = cli("register", tmp_path / "a" / "." / "merged.ply", tmp_path / "b.ply", "--out", a / ".." / "a")
    assert_error(run, 2, "merged.ply", "this command's input", "--force")
    assert _tree(a) == before


def test_a_file_output_that_is_the_input(cli, tmp_path):
    cloud = tmp_path / "cloud.ply"
    cloud.write_text("points")
    run = cli("mesh", tmp_path / "." / "cloud.ply", "--out", cloud)
    assert_error(run, 2, f"--out {cloud}", "is this command's input", "--force")
    assert cloud.read_text() == "points"


def test_claim_folder_refuses_an_input_even_in_its_own_set(tmp_path):
    (tmp_path / "poses.json").write_text("{}")
    (tmp_path / "mesh.ply").write_text("an input")
    with pytest.raises(UsageError, match=r"mesh.ply is this command's input .*--force"):
        claim_folder(tmp_path, "registration", force=False, inputs=[tmp_path / "mesh.ply"],
                     names=("poses.json", "merged.ply"))     # --no-mesh would remove it after the run
    replace = claim_folder(tmp_path, "registration", force=True, inputs=[tmp_path / "mesh.ply"])
    assert replace() == ["poses.json"]                   # an input is never removed
    assert (tmp_path / "mesh.ply").read_text() == "an input"


def test_depth_maps_are_a_set_of_their_own(tmp_path):
    (tmp_path / "depth.png").write_bytes(b"png")
    (tmp_path / "cloud.ply").write_text("old")
    assert file_owner(tmp_path / "cloud.ply").name == "depth"
    claim_folder(tmp_path, "depth", force=False)         # a rerun of tof or stereo
    with pytest.raises(UsageError, match="holds depth maps"):
        claim_folder(tmp_path, "registration", force=False)


def test_a_rerun_into_its_input_folder_writes_its_own_files_and_removes_no_input(tmp_path):
    (tmp_path / "normals.npy").write_bytes(b"an earlier run's")      # photometric DIR --out DIR, run before
    (tmp_path / "mask.png").write_bytes(b"an input")
    claim_folder(tmp_path, "photometric", force=False, inputs=[tmp_path])   # its own set: not refused
    (tmp_path / "ground_truth.npz").write_bytes(b"a capture")       # tof RAW --out RAW --force
    (tmp_path / "tof.json").write_text("{}")
    (tmp_path / "normals.npy").unlink()
    replace = claim_folder(tmp_path, "depth", force=True, inputs=[tmp_path])
    assert replace() == [] and (tmp_path / "tof.json").exists()      # the input folder's files stay
