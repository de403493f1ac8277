"""Issue 34, silent wrong results from units and scale: each input below used to exit 0 without a word; now it
is refused (or warned of) naming the value and the unit its numbers look like.

- ``rig import`` of an OpenCV calibration whose ``T`` is in millimetres read as metres (a 200 m baseline), of a
  zero ``T``, and ``--unit mm`` on a file in metres (a 0.2 mm baseline); an unusual but possible baseline warns;
- ``stereo --rig`` with a stereo rig file in millimetres (a 75 m baseline: every depth 1000 times too far);
- ``sim render --object`` of a mesh in millimetres (an object 88 m across around the rig), and
  ``--object-unit mm`` reading it right;
- ``register`` with a mirrored scan (x negated) that the prior holds close enough for its edges to pass.

Rules: :mod:`rangekit.rig.plausibility`; the mirrored scan: :mod:`rangekit.app.commands.handedness`.
"""

from __future__ import annotations

import json

import cv2
import numpy as np
import pytest

from support.cli_runs import assert_error
from rangekit.formats.clouds import save_cloud
from rangekit.formats.poses import save_poses
from rangekit.geometry import apply_T, axis_angle_to_R, invert_T, make_T
from rangekit.rig.plausibility import BASELINE, OBJECT_SIZE, likely_unit
from rangekit.surface.cloud import PointCloud

K_CAM = np.array([[1000.0, 0.0, 639.5], [0.0, 1000.0, 399.5], [0.0, 0.0, 1.0]])
K_PROJ = np.array([[1500.0, 0.0, 639.5], [0.0, 1500.0, 399.5], [0.0, 0.0, 1.0]])


def _opencv_calibration(path, T):
    """A camera-projector calibration as cv2.stereoCalibrate's caller writes it, with translation ``T``."""
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for key, value in dict(K1=K_CAM, D1=np.zeros((1, 5)), K2=K_PROJ, D2=np.zeros((1, 5)), R=np.eye(3),
                           T=np.array(T, float).reshape(3, 1), imageSize=np.array([1280, 800]),
                           projectorSize=np.array([1280, 800])).items():
        fs.write(key, value)
    fs.release()
    return path


# ----------------------------------------------------------------------------- the rules
def test_the_rules_refuse_zero_and_far_outside_warn_near_and_guess_the_unit():
    assert [BASELINE.verdict(b) for b in (0.0, 0.0009, 0.003, 0.075, 1.9, 5.0, 200.0, np.nan)] == \
        ["refuse", "refuse", "warn", "ok", "ok", "warn", "refuse", "refuse"]
    assert [OBJECT_SIZE.verdict(d) for d in (0.0005, 0.1, 4.0, 87.7)] == ["refuse", "ok", "warn", "refuse"]
    assert likely_unit(200.0, BASELINE, "m") == "mm"          # 200 mm
    assert likely_unit(0.0002, BASELINE, "mm") == "m"         # 0.2 m
    assert likely_unit(0.0, BASELINE, "m") is None
    assert likely_unit(3.0, BASELINE, "m", units=("m", "mm")) is None    # 3 cm would do, but no option reads cm


# ----------------------------------------------------------------------------- rig import
def test_rig_import_refuses_a_file_in_millimetres_read_as_metres(cli, tmp_path):
    src = _opencv_calibration(tmp_path / "stereo.yaml", [200, 0, 0])
    line = assert_error(cli("rig", "import", src, "--out", tmp_path / "rig.json"), 1, src,
                        "T = (200, 0, 0) m", "a 200 m camera-projector baseline", "looks like millimetres",
                        "use --unit mm")
    assert not (tmp_path / "rig.json").exists(), line
    run = cli("rig", "import", src, "--unit", "mm", "--out", tmp_path / "rig.json")     # the fix it names
    assert run.code == 0, run.err
    T_world_proj = np.array(json.loads((tmp_path / "rig.json").read_text())["projector"]["T_world_cam"])
    np.testing.assert_allclose(T_world_proj[:3, 3], [-0.2, 0.0, 0.0], atol=1e-15)


def test_rig_import_refuses_a_zero_baseline(cli, tmp_path):
    src = _opencv_calibration(tmp_path / "stereo.yml", [0, 0, 0])
    assert_error(cli("rig", "import", src), 1, src, "T = (0, 0, 0) m", "a zero camera-projector baseline",
                 "expected 5 mm to 2 m")


def test_rig_import_refuses_unit_mm_on_a_file_in_metres(cli, tmp_path):
    src = _opencv_calibration(tmp_path / "stereo.xml", [0.2, 0, 0])
    assert_error(cli("rig", "import", src, "--unit", "mm"), 1, src, "T = (0.2, 0, 0) mm",
                 "a 0.2 mm camera-projector baseline", "looks like metres", "use --unit m")
    run = cli("rig", "import", src)
    assert run.code == 0 and "warning" not in run.err, run.err


def test_rig_import_warns_of_an_unusual_baseline_and_goes_on(cli, tmp_path):
    src = _opencv_calibration(tmp_path / "wide.yaml", [3, 0, 0])
    run = cli("rig", "import", src)
    assert run.code == 0, run.err
    assert "rangekit: warning: " in run.err and "a 3 m camera-projector baseline, outside the usual 5 mm to 2 m" \
        in run.err, run.err
    assert json.loads(run.out)["projector"] is not None


def test_depthai_translations_are_checked_in_their_centimetres(tmp_path):
    from rangekit.errors import ConfigError
    from rangekit.formats.rig_files.importers import import_rig

    def eeprom(t_cm):
        cam = {"width": 1280, "height": 800, "intrinsicMatrix": K_CAM.tolist(), "distortionCoeff": [0.0] * 14}
        right = dict(cam, extrinsics={"rotationMatrix": np.eye(3).tolist(), "toCameraSocket": 1,
                                      "translation": dict(zip("xyz", t_cm))})
        path = tmp_path / "eeprom.json"
        path.write_text(json.dumps({"cameraData": [[1, cam], [2, right]]}))
        return path

    assert len(import_rig(eeprom([-7.5, 0, 0]))["cameras"]) == 2
    with pytest.raises(ConfigError, match=r"cameraData\[1\].extrinsics.translation = \(-0.075, 0, 0\) cm: a 0.75 mm "
                                          r"baseline from socket 2 to socket 1; the file looks like metres"):
        import_rig(eeprom([-0.075, 0, 0]))          # written in metres by hand: depthai's are centimetres
    with pytest.raises(ConfigError, match=r"\(0, 0, 0\) cm: a zero baseline from socket 2 to socket 1"):
        import_rig(eeprom([0, 0, 0]))


# ----------------------------------------------------------------------------- stereo
def test_stereo_refuses_a_rig_file_in_millimetres(cli, tmp_path):
    assert cli("sim", "render", "--sensor", "stereo", "--size", "64x40", "--out", tmp_path / "pair").code == 0
    rig = json.loads((tmp_path / "pair" / "rig.json").read_text())
    for device in rig["cameras"] + [rig["projector"]]:
        for row in device["T_world_cam"][:3]:
            row[3] *= 1000.0                                   # the same rig, written in millimetres
    (tmp_path / "rig_mm.json").write_text(json.dumps(rig))
    pair = [tmp_path / "pair" / "left.png", tmp_path / "pair" / "right.png"]
    line = assert_error(cli("stereo", *pair, "--rig", tmp_path / "rig_mm.json", "--out", tmp_path / "depth"), 1,
                        "rig_mm.json", "cameras[1] ('right') is (75, 0.3, -0.2) m from cameras[0] ('left')",
                        "a 75 m stereo baseline", "the rig file looks like millimetres",
                        "divide every T_world_cam translation by 1000")
    assert not (tmp_path / "depth").exists(), line


# ----------------------------------------------------------------------------- sim render --object
@pytest.fixture
def box_mm(tmp_path):
    import trimesh

    path = tmp_path / "box_mm.ply"
    trimesh.creation.box(extents=(60.0, 50.0, 40.0)).export(path)      # a 60 x 50 x 40 mm box, in mm
    return path


def test_sim_render_refuses_a_mesh_in_millimetres(cli, tmp_path, box_mm):
    for sensor in ("projector", "laser"):
        line = assert_error(cli("sim", "render", "--sensor", sensor, "--object", box_mm, "--out", tmp_path / sensor),
                            1, box_mm, "bounding box (60, 50, 40) m", "a 87.7 m object",
                            "the file looks like millimetres", "use --object-unit mm")
        assert not (tmp_path / sensor).exists(), line
    assert_error(cli("sim", "render", "--object", "lumpy", "--object-unit", "mm", "--out", tmp_path / "o"), 2,
                 "--object-unit mm", "only for a mesh file")


def test_sim_render_object_unit_mm_renders_the_box_at_its_size(cli, tmp_path, box_mm, small_rig):
    from rangekit.rig.rig_file import save_rig

    save_rig(small_rig, tmp_path / "rig.json")
    out = tmp_path / "cap"
    run = cli("sim", "render", "--object", box_mm, "--object-unit", "mm", "--rig", tmp_path / "rig.json",
              "--patterns", "white", "--no-noise", "--out", out)
    assert run.code == 0, run.err
    assert json.loads((out / "capture.json").read_text())["object_unit"] == "mm"
    truth = np.load(out / "ground_truth.npz")
    on_box = truth["xyz"][truth["hit"]]
    on_box = on_box[on_box[:, 2] > 0.5e-3]                    # above the turntable's top
    assert len(on_box) > 100
    assert on_box[:, 2].max() == pytest.approx(0.040, abs=1e-6)      # its top: the box's 40 mm height, in metres
    assert np.ptp(on_box[:, 0]) == pytest.approx(0.060, abs=1e-3)    # its 60 mm width, seen by 320 pixels


# ----------------------------------------------------------------------------- register, a mirrored scan
RADII = np.array([0.05, 0.035, 0.025])
# Five low bumps at places no reflection maps onto each other: an egg that is almost, not quite, symmetric,
# so a mirrored view still fits with an RMS residual under the acceptance gate (about 0.3 voxel).
BUMPS = np.array([[0.8, 0.5, 0.3], [-0.3, 0.9, -0.2], [0.2, -0.6, 0.75], [-0.7, -0.4, -0.55], [0.1, 0.3, -0.95]])


def _egg_views(tmp_path, mirrored: int | None, n_views: int = 4, n: int = 3000):
    """Scans of the egg from ``n_views`` sides (each in its own frame) and their true poses as poses.json;
    scan ``mirrored`` with x negated."""
    rng = np.random.default_rng(0)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    b = BUMPS / np.linalg.norm(BUMPS, axis=1, keepdims=True)
    p = d * (1 + 0.05 * np.exp(-np.sum((d[:, None] - b[None]) ** 2, axis=2) / 0.08).sum(axis=1))[:, None] * RADII
    paths, poses = [], []
    for k in range(n_views):
        a = 2 * np.pi * k / n_views
        T = make_T(axis_angle_to_R([0.1, 0.2, 1.0], a), [0.004 * k, -0.003 * k, 0.002])
        side = np.array([np.cos(a), np.sin(a), 0.3])
        pts = apply_T(invert_T(T), p[(p / RADII) @ side > 0.1 * np.linalg.norm(side)])
        if k == mirrored:
            pts = pts * [-1.0, 1.0, 1.0]
        paths.append(tmp_path / f"scan{k}.ply")
        save_cloud(paths[-1], PointCloud(pts))
        poses.append(T)
    save_poses(tmp_path / "poses.json", [p.name for p in paths], np.stack(poses))
    return paths, tmp_path / "poses.json"


def test_register_names_a_mirrored_scan(cli, tmp_path):
    paths, poses = _egg_views(tmp_path, mirrored=1)
    line = assert_error(cli("register", *paths, "--init", poses, "--no-mesh", "--out", tmp_path / "reg"), 1,
                        "scan1.ply looks mirrored", "handedness", "negate one axis")
    assert not (tmp_path / "reg").exists(), line


def test_register_of_the_same_scans_unmirrored_is_not_flagged(cli, tmp_path):
    paths, poses = _egg_views(tmp_path, mirrored=None)
    run = cli("register", *paths, "--init", poses, "--no-mesh", "--out", tmp_path / "reg")
    assert run.code == 0, run.err
    assert "mirrored" not in run.err + run.out
