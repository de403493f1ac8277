"""The command line: help on every command, sim render output, clean errors."""

import subprocess
import sys

import numpy as np
import pytest

from rangekit.cli import main
from rangekit.io import read_png
from rangekit.coded.patterns import PatternSpec
from rangekit.io import read_json
from rangekit.rig.rig_file import load_rig


@pytest.mark.parametrize("argv", [["--help"], ["sim", "--help"], ["sim", "render", "--help"], ["decode", "--help"],
                                  ["reconstruct", "--help"], ["register", "--help"], ["mesh", "--help"],
                                  ["scan", "--help"], ["devices", "--help"], ["process", "--help"],
                                  ["render", "--help"], ["rig", "--help"], ["rig", "init", "--help"],
                                  ["calibrate", "--help"], ["photometric", "--help"]])
def test_every_command_has_help(argv, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 0
    assert "usage: rangekit" in capsys.readouterr().out


def test_sim_render_writes_captures_truth_rig_and_preview(tmp_path):
    out = tmp_path / "cap"
    assert main(["sim", "render", "--object", "sphere", "--out", str(out), "--seed", "1"]) == 0
    spec = PatternSpec.from_dict(read_json(out / "patterns.json"))
    pngs = sorted(out.glob("[0-9][0-9][0-9].png"))
    assert len(pngs) == spec.n_frames == 44
    white, black = read_png(pngs[0]), read_png(pngs[1])
    assert white.shape == (1024, 1280) and white.dtype == np.uint8
    gt = np.load(out / "ground_truth.npz")
    assert set(gt.files) >= {"depth", "xyz", "normals", "proj_col", "proj_row", "valid"}
    valid = gt["valid"]
    assert gt["depth"].shape == (1024, 1280) and gt["xyz"].shape == (1024, 1280, 3)
    assert np.all(np.isnan(gt["proj_col"][~valid])) and np.all(np.isfinite(gt["proj_col"][valid]))
    assert np.all(np.isnan(gt["depth"][~gt["hit"]]))
    # Lit pixels are brighter under white than under black; the true depth is near the working distance.
    assert np.mean(white[valid].astype(int) - black[valid]) > 40
    assert 0.4 < np.nanmedian(gt["depth"][valid]) < 0.6
    rig = load_rig(out / "rig.json")
    assert rig.camera.width == 1280 and rig.projector.width == 1280
    assert read_png(out / "preview.png").ndim == 3


def test_sim_render_16_bit_and_white_pattern(tmp_path):
    out = tmp_path / "w"
    assert main(["sim", "render", "--object", "box", "--patterns", "white", "--bits", "12",
                 "--out", str(out)]) == 0
    img = read_png(out / "000.png")
    assert img.dtype == np.uint16 and 0 < img.max() <= 4095
    assert not (out / "001.png").exists()


def test_cli_errors_are_one_line_without_traceback(tmp_path):
    bad = tmp_path / "bad.ply"
    bad.write_bytes(b"ply\nformat nonsense\n")
    proc = subprocess.run([sys.executable, "-m", "rangekit", "sim", "render", "--object", str(bad), "--out",
                           str(tmp_path / "o")], capture_output=True, text=True)
    assert proc.returncode == 1
    assert "bad.ply" in proc.stderr and "Traceback" not in proc.stderr


@pytest.mark.slow
def test_decode_and_reconstruct_commands(tmp_path):
    cap = tmp_path / "cap"
    assert main(["sim", "render", "--object", "sphere", "--patterns", "hybrid", "--out", str(cap)]) == 0
    maps = tmp_path / "maps.npz"
    assert main(["decode", str(cap), "--pattern", str(cap / "patterns.json"), "--out", str(maps)]) == 0
    gt = np.load(cap / "ground_truth.npz")
    with np.load(maps) as m:
        assert {"proj_col", "proj_row", "confidence", "shadow"} <= set(m.files)
        err = m["proj_col"][gt["valid"]] - gt["proj_col"][gt["valid"]]
        assert np.nanmedian(np.abs(err)) < 0.1 and np.isfinite(err).mean() > 0.95
    # The same images as a list of files with a method name and projector size.
    files = [str(p) for p in sorted(cap.glob("[0-9][0-9][0-9].png"))]
    packed = tmp_path / "packed.npz"
    assert main(["decode", *files, "--pattern", "hybrid", "--projector", "1280x800", "--compress",
                 "--out", str(packed)]) == 0
    with np.load(maps) as m, np.load(packed) as p:       # the same maps, deflated
        assert m.files == p.files and all(np.array_equal(m[k], p[k], equal_nan=True) for k in m.files)
    assert packed.stat().st_size < maps.stat().st_size / 3
    cloud = tmp_path / "sphere.ply"
    assert main(["reconstruct", str(cap), "--out", str(cloud)]) == 0
    import open3d as o3d

    pc = o3d.io.read_point_cloud(str(cloud))
    P = np.asarray(pc.points)
    assert len(P) > 50000 and pc.has_colors() and pc.has_normals()
    on_sphere = np.abs(np.linalg.norm(P - [0, 0, 0.05], axis=1) - 0.05) < 1e-3
    assert on_sphere.sum() > 50000  # the sphere stands on the table, centre 5 cm up


def test_decode_command_errors(tmp_path, capsys):
    cap = tmp_path / "w"
    assert main(["sim", "render", "--object", "plane", "--patterns", "white", "--out", str(cap)]) == 0
    assert main(["decode", str(cap), "--pattern", "graycode", "--projector", "1280x800",
                 "--out", str(tmp_path / "m.npz")]) == 1
    assert "found 1 captures" in capsys.readouterr().err
    assert main(["decode", str(cap), "--pattern", "graycode", "--out", str(tmp_path / "m.npz")]) == 2
    assert "--projector" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["decode", str(cap), "--pattern", "graycode", "--projector", "1280by800", "--out", "x.npz"])




@pytest.mark.slow
def test_register_and_mesh_commands(tmp_path, capsys):
    from support.shared_data import require_shared

    bunny = require_shared("stanford-bunny")
    scans = [str(bunny / n) for n in ("bun000.ply", "bun045.ply", "bun315.ply", "chin.ply")]
    out = tmp_path / "reg"
    assert main(["register", *scans, "--init", "none", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "synchronisation over" in text and "rmse" in text
    from rangekit.formats.meshes import load_mesh
    from rangekit.formats.poses import load_poses

    sources, T = load_poses(out / "poses.json")
    assert [s.split("/")[-1] for s in sources] == ["bun000.ply", "bun045.ply", "bun315.ply", "chin.ply"]
    assert np.allclose(T[0], np.eye(4))
    assert 20 < np.degrees(np.arccos((np.trace(T[1][:3, :3]) - 1) / 2)) < 50  # bun045 is ~34 deg from bun000
    mesh = load_mesh(out / "mesh.ply")
    assert mesh.is_watertight and len(mesh.triangles) > 1000
    # The poses file seeds a second run; a turntable prior parses.
    assert main(["register", *scans, "--init", str(out / "poses.json"), "--no-mesh", "--out", str(tmp_path / "r2")]) == 0
    assert main(["mesh", str(out / "merged.ply"), "--depth", "7", "--out", str(tmp_path / "m.ply")]) == 0
    assert main(["register", *scans, "--init", "turntable:0,1:24", "--out", str(tmp_path / "r3")]) == 2
    assert "turntable:AX,AY,AZ:STEP_DEG" in capsys.readouterr().err


def test_scan_command_acquires_and_resumes(tmp_path, capsys):
    out = tmp_path / "scan"
    assert main(["scan", "--out", str(out), "--views", "2", "--patterns", "hybrid", "--object", "sphere",
                 "--no-process"]) == 0
    assert main(["scan", "--out", str(out), "--views", "2"]) == 2
    assert "already holds a session" in capsys.readouterr().err
    assert main(["scan", "--resume", str(out), "--no-process"]) == 0
    assert "2/2 views already done" in capsys.readouterr().err    # progress: on stderr
    # Each view is a capture folder that reconstructs on its own.
    assert main(["reconstruct", str(out / "view_001"), "--out", str(tmp_path / "v1.ply")]) == 0
    from rangekit.formats.clouds import load_cloud

    P = load_cloud(tmp_path / "v1.ply").points
    assert len(P) > 20000


def test_scan_with_a_bad_rig_file_fails_before_anything_moves(tmp_path, capsys):
    import json

    from rangekit.sim import default_rig

    data = default_rig().to_dict()
    data["devices"] = {"turntable": {"protocol": "horus", "port": str(tmp_path / "no-such-port")},
                       "projector": {"display": 1}, "camera": {"type": "depthai"}}
    rig_file = tmp_path / "rig.json"
    rig_file.write_text(json.dumps(data))
    assert main(["scan", "--rig", str(rig_file), "--out", str(tmp_path / "s")]) == 1
    assert "no-such-port" in capsys.readouterr().err
    assert not (tmp_path / "s" / "session.json").exists()
    data["devices"]["turntable"]["protocol"] = "stepper9000"
    rig_file.write_text(json.dumps(data))
    assert main(["scan", "--rig", str(rig_file), "--out", str(tmp_path / "s")]) == 1
    assert "devices.turntable.protocol" in capsys.readouterr().err
    data["cameras"][0]["K"] = [[1, 0], [0, 1]]
    rig_file.write_text(json.dumps(data))
    assert main(["scan", "--rig", str(rig_file), "--out", str(tmp_path / "s")]) == 1
    err = capsys.readouterr().err
    assert "cameras[0]" in err and "'K'" in err


def test_processing_and_the_cli_leave_the_work_to_the_library():
    """Processing never imports the simulator (the evaluator is passed in); cli modules only parse,
    call the library and print (numpy at most for formatting)."""
    import ast
    from pathlib import Path

    root = Path(__file__).resolve().parents[2] / "rangekit"

    def imported(path):
        names = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names |= {a.name for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module:
                names.add(node.module)
        return names

    for path in sorted([*(root / "app" / "process").glob("*.py"), *(root / "app" / "report").glob("*.py")]):
        assert not [m for m in imported(path) if m.startswith("rangekit.sim")], path.name
    for path in sorted((root / "cli").glob("*.py")):
        calls = {n.func.attr for n in ast.walk(ast.parse(path.read_text()))
                 if isinstance(n, ast.Call) and isinstance(n.func, ast.Attribute)
                 and isinstance(n.func.value, ast.Name) and n.func.value.id == "np"}
        assert calls <= {"radians", "degrees", "asarray", "mean", "max", "linalg"}, (path.name, calls)
