"""``rangekit rig import`` of structured-light tools' calibration files (rangekit/formats/rig_files/import_tools.py),
each written here in the tool's own layout from a known rig: kamino410 procam-calibration's
calibration_result.xml, Moreno-Taubin scan3d-capture's calibration.yml and OpenCV's structured_light sample's
two-camera calibration. Every number comes back; the pose has the direction and the unit of its source, so a
transpose, an inverse, a sign or a factor of 1000 fails. (SLStudio's file: tests/formats/test_rig_import.py.)"""

import json

import cv2
import numpy as np
import pytest

from support.cli_runs import assert_error
from rangekit.errors import ConfigError
from rangekit.formats.rig_files.importers import import_rig
from rangekit.geometry import invert_T
from rangekit.rig.rig_file import load_rig

# A rig with nothing symmetric: cx != cy, fx != fy, a rotation about every axis, a translation (mm) on every axis.
K_CAM = np.array([[3452.39250438, 0.0, 587.172935], [0.0, 3449.92385141, 521.44584352], [0.0, 0.0, 1.0]])
D_CAM = np.array([[-0.2222626239, -0.8664324581, -7.2788770e-04, -1.6884096e-03, 3.1325279903]])
K_PROJ = np.array([[1947.158035, 0.0, 448.863528], [0.0, 1933.992186, 719.974914], [0.0, 0.0, 1.0]])
D_PROJ = np.array([[-0.0912255446, 1.1448484379, -2.2695481e-03, -9.3122930e-03, -7.7979215527]])
R = cv2.Rodrigues(np.array([[0.0612], [-0.0413], [0.0133]]))[0]
T_MM = np.array([[39.0631122419], [-278.2644827559], [-61.9473821526]])
CAM_W, CAM_H, PROJ_W, PROJ_H = 1280, 1024, 912, 1140


def _write(path, values: dict):
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for k, v in values.items():
        fs.write(k, v)
    fs.release()
    return path


def _kamino(path, *, rotation_key="roration", **change):
    """calibration_result.xml as kamino410's calibrate.py writes it: img_shape is the camera image's numpy shape
    (rows, cols), the rest stereoCalibrate's outputs in the square size's unit."""
    values = {"img_shape": (CAM_H, CAM_W), "rms": 0.4254, "cam_int": K_CAM, "cam_dist": D_CAM, "proj_int": K_PROJ,
              "proj_dist": D_PROJ, rotation_key: R, "translation": T_MM}
    values.update(change)
    return _write(path, {k: v for k, v in values.items() if v is not None})


def _moreno_taubin(path, *, early=False, **change):
    """calibration.yml as scan3d-capture's CalibrationData::save_calibration_yml writes it (``early``: the first
    Application::calibrate, b and m instead of the per-device errors)."""
    values = {"cam_K": K_CAM, "cam_kc": D_CAM, "proj_K": K_PROJ, "proj_kc": D_PROJ, "R": R, "T": T_MM}
    values.update({"b": 0.3, "m": 5} if early else {"cam_error": 0.21, "proj_error": 0.35})
    values["stereo_error"] = 0.42
    values.update(change)
    return _write(path, {k: v for k, v in values.items() if v is not None})


def _matrix_yaml(name, m):
    m = np.atleast_2d(m)
    data = ", ".join(repr(float(x)) for x in m.ravel())
    return f"{name}: !!opencv-matrix\n   rows: {m.shape[0]}\n   cols: {m.shape[1]}\n   dt: d\n   data: [ {data} ]\n"


def _opencv_sample(path, *, sizes=True, T=T_MM):
    """calibrationParameters.yml in the layout of opencv_extra's structured_light test data (as pointcloud.cpp
    and test_plane.cpp read it): %YAML:1.0, cam1_size / cam2_size as [width, height] sequences."""
    text = "%YAML:1.0\n" + _matrix_yaml("cam1_intrinsics", K_CAM) + _matrix_yaml("cam1_distorsion", D_CAM)
    text += f"cam1_size: [ {CAM_W}, {CAM_H} ]\n" if sizes else ""
    text += _matrix_yaml("cam2_intrinsics", K_PROJ) + _matrix_yaml("cam2_distorsion", D_PROJ)
    text += f"cam2_size: [ {PROJ_W}, {PROJ_H} ]\n" if sizes else ""
    text += _matrix_yaml("R", R) + _matrix_yaml("T", T) + "stereo_error: 9.6332463967109194e-01\n"
    path.write_text(text)
    return path


def _assert_pose(T_world_first, T_world_second, T_mm=T_MM):
    """X_second = R X_first + T (mm -> m): cv2.stereoCalibrate's convention."""
    T_second_first = invert_T(T_world_second) @ T_world_first
    np.testing.assert_allclose(T_second_first[:3, :3], R, rtol=0, atol=1e-12)
    np.testing.assert_allclose(T_second_first[:3, 3], np.ravel(T_mm) / 1000, rtol=0, atol=1e-12)
    np.testing.assert_allclose(T_world_first, np.eye(4), rtol=0, atol=0)


# ----------------------------------------------------------------------------- kamino410 procam-calibration
@pytest.mark.parametrize("rotation_key", ["roration", "rotation"])   # the typo of its sample, a later fix
def test_kamino410_calibration_result_round_trips(cli, tmp_path, rotation_key):
    src = _kamino(tmp_path / "calibration_result.xml", rotation_key=rotation_key)
    run = cli("rig", "import", src, "--projector-size", f"{PROJ_W}x{PROJ_H}", "--out", tmp_path / "rig.json")
    assert run.code == 0, run.err
    assert "read as kamino410 procam-calibration's calibration_result.xml; translation in millimetres" in run.err
    rig = load_rig(tmp_path / "rig.json")
    cam, proj = rig.camera, rig.projector
    assert (cam.width, cam.height, proj.width, proj.height) == (CAM_W, CAM_H, PROJ_W, PROJ_H)   # img_shape: rows first
    np.testing.assert_allclose(cam.K, K_CAM, rtol=0, atol=1e-12)
    np.testing.assert_allclose(proj.K, K_PROJ, rtol=0, atol=1e-12)
    np.testing.assert_allclose(cam.dist, D_CAM.ravel(), rtol=0, atol=1e-15)
    np.testing.assert_allclose(proj.dist, D_PROJ.ravel(), rtol=0, atol=1e-15)
    _assert_pose(cam.T_world_cam, proj.T_world_cam)
    assert len(rig.cameras) == 1 and rig.T_world_table is None


def test_kamino410_needs_the_projector_size_and_reads_other_units_when_told(cli, tmp_path):
    src = _kamino(tmp_path / "calibration_result.xml")
    assert_error(cli("rig", "import", src), 1, src, "expected the projector size", "found none in the file",
                 "give it with --projector-size WxH")
    metres = _kamino(tmp_path / "in_m.xml", translation=T_MM / 1000)       # a square size given in metres
    assert_error(cli("rig", "import", metres, "--projector-size", "912x1140"), 1, metres,
                 "translation = (0.03906, -0.2783, -0.06195) mm", "a 0.288 mm camera-projector baseline",
                 "looks like metres", "use --unit m")
    for unit, scale in (("m", 1e-3), ("cm", 1e-1)):
        src = _kamino(tmp_path / f"in_{unit}.xml", translation=T_MM * scale)
        data = import_rig(src, projector_size=(PROJ_W, PROJ_H), unit=unit)
        _assert_pose(np.array(data["cameras"][0]["T_world_cam"]), np.array(data["projector"]["T_world_cam"]))


def test_kamino410_rotation_in_float32_is_reorthonormalised_and_a_scaled_one_refused(cli, tmp_path):
    near = _kamino(tmp_path / "f32.xml", roration=R.astype(np.float32))      # orthonormal to ~1e-7 only
    data = import_rig(near, projector_size=(PROJ_W, PROJ_H))
    R_read = np.array(data["projector"]["T_world_cam"])[:3, :3].T
    np.testing.assert_allclose(R_read @ R_read.T, np.eye(3), rtol=0, atol=1e-14)
    np.testing.assert_allclose(R_read, R, rtol=0, atol=1e-6)
    scaled = _kamino(tmp_path / "scaled.xml", roration=R * 1.01)
    assert_error(cli("rig", "import", scaled, "--projector-size", "912x1140"), 1, scaled,
                 "roration: expected a 3x3 rotation (orthonormal within 1e-06, determinant +1)",
                 "found max |R R^T - I| = 0.02")


@pytest.mark.parametrize("change, mentions", [
    ({"proj_dist": None}, ["proj_dist: expected a matrix (the projector distortion of kamino410",
                           "found no such key; the file has img_shape, rms, cam_int"]),
    ({"proj_int": K_PROJ[:2]}, ["proj_int: expected a finite 3x3 camera matrix, found shape (2, 3)"]),
    ({"cam_int": K_CAM * np.array([[-1.0], [1.0], [1.0]])}, ["cam_int: expected positive focal lengths fx, fy "
                                                              "(pixels), found fx = -3452.39, fy = 3449.92"]),
    ({"cam_dist": D_CAM[:, :3]}, ["cam_dist: expected 4, 5, 8, 12 or 14 finite OpenCV distortion coefficients, "
                                  "found 3"]),
    ({"translation": np.array([[1.0], [2.0]])}, ["translation: expected 3 finite numbers, found [1.0, 2.0]"]),
    ({"img_shape": (0, 1280)}, ["img_shape: expected [height, width] in pixels, found [[0.0], [1280.0]]"]),
    ({"img_shape": "1024x1280"}, ["img_shape: expected a matrix or numbers, found the text '1024x1280'"]),
])
def test_kamino410_bad_values_are_refused_by_key(cli, tmp_path, change, mentions):
    src = _kamino(tmp_path / "calibration_result.xml", **change)
    assert_error(cli("rig", "import", src, "--projector-size", "912x1140"), 1, src, *mentions)


# ----------------------------------------------------------------------------- Moreno-Taubin scan3d-capture
@pytest.mark.parametrize("early", [False, True])
def test_moreno_taubin_calibration_yml_round_trips_with_the_sizes_given(cli, tmp_path, early):
    src = _moreno_taubin(tmp_path / "calibration.yml", early=early)
    assert_error(cli("rig", "import", src, "--projector-size", "912x1140"), 1, src,
                 "expected the camera image size", "give it with --size WxH")
    assert_error(cli("rig", "import", src, "--size", "1280x1024"), 1, src, "expected the projector size",
                 "give it with --projector-size WxH")
    run = cli("rig", "import", src, "--size", f"{CAM_W}x{CAM_H}", "--projector-size", f"{PROJ_W}x{PROJ_H}")
    assert run.code == 0, run.err
    assert "read as Moreno-Taubin scan3d-capture's calibration.yml; T in millimetres" in run.err
    data = json.loads(run.out)
    cam, proj = data["cameras"][0], data["projector"]
    assert (cam["width"], cam["height"], proj["width"], proj["height"]) == (CAM_W, CAM_H, PROJ_W, PROJ_H)
    np.testing.assert_allclose(cam["K"], K_CAM, rtol=0, atol=1e-12)
    np.testing.assert_allclose(proj["K"], K_PROJ, rtol=0, atol=1e-12)
    np.testing.assert_allclose(cam["dist"], D_CAM.ravel(), rtol=0, atol=1e-15)
    np.testing.assert_allclose(proj["dist"], D_PROJ.ravel(), rtol=0, atol=1e-15)
    _assert_pose(np.array(cam["T_world_cam"]), np.array(proj["T_world_cam"]))


def test_moreno_taubin_bad_values_are_refused_by_key_and_plain_cam_K_files_stay_opencv(cli, tmp_path):
    sizes = ("--size", "1280x1024", "--projector-size", "912x1140")
    src = _moreno_taubin(tmp_path / "a.yml", proj_K=None)
    assert_error(cli("rig", "import", src, *sizes), 1, src, "proj_K: expected a matrix (the projector matrix of "
                 "Moreno-Taubin scan3d-capture's calibration.yml), found no such key")
    src = _moreno_taubin(tmp_path / "b.yml", R=np.diag([1.0, -1.0, 1.0]))              # a reflection
    assert_error(cli("rig", "import", src, *sizes), 1, src, "R: expected a 3x3 rotation", "det -1")
    src = _moreno_taubin(tmp_path / "c.yml", proj_K=np.array([[1900.0, 0, 450], [0, 0.0, 720], [0, 0, 1]]))
    assert_error(cli("rig", "import", src, *sizes), 1, src, "proj_K: expected positive focal lengths", "fy = 0")
    # Without stereo_error, cam_K/cam_kc/proj_K/proj_kc/R/T is a plain OpenCV stereo file: T in metres.
    plain = _write(tmp_path / "plain.yml", {"cam_K": K_CAM, "cam_kc": D_CAM, "proj_K": K_PROJ, "proj_kc": D_PROJ,
                                            "R": R, "T": T_MM / 1000})
    data = import_rig(plain, size=(CAM_W, CAM_H), projector_size=(PROJ_W, PROJ_H))
    _assert_pose(np.array(data["cameras"][0]["T_world_cam"]), np.array(data["projector"]["T_world_cam"]))


# ----------------------------------------------------------------------------- OpenCV structured_light sample
def test_opencv_sample_calibration_gives_two_cameras(cli, tmp_path):
    src = _opencv_sample(tmp_path / "calibrationParameters.yml")
    run = cli("rig", "import", src, "--out", tmp_path / "rig.json")
    assert run.code == 0, run.err
    assert "wrote" in run.out and "2 camera(s)" in run.out
    assert "read as OpenCV structured_light sample's calibration; T in millimetres" in run.err
    rig = load_rig(tmp_path / "rig.json")
    assert rig.projector is None and [c.name for c in rig.cameras] == ["cam1", "cam2"]
    cam1, cam2 = rig.cameras
    assert (cam1.width, cam1.height, cam2.width, cam2.height) == (CAM_W, CAM_H, PROJ_W, PROJ_H)   # [width, height]
    np.testing.assert_allclose(cam1.K, K_CAM, rtol=0, atol=1e-12)
    np.testing.assert_allclose(cam2.K, K_PROJ, rtol=0, atol=1e-12)
    np.testing.assert_allclose(cam1.dist, D_CAM.ravel(), rtol=0, atol=1e-15)
    np.testing.assert_allclose(cam2.dist, D_PROJ.ravel(), rtol=0, atol=1e-15)
    _assert_pose(cam1.T_world_cam, cam2.T_world_cam)                     # X_cam2 = R X_cam1 + T


def test_opencv_sample_without_sizes_takes_one_size_for_both_and_refuses_a_projector_size(cli, tmp_path):
    src = _opencv_sample(tmp_path / "calib.yml", sizes=False)
    assert_error(cli("rig", "import", src), 1, src, "expected the first camera's image size",
                 "found no cam1_size in the file", "give it with --size WxH")
    data = import_rig(src, size=(1920, 1280))
    assert [(c["width"], c["height"]) for c in data["cameras"]] == [(1920, 1280), (1920, 1280)]
    assert_error(cli("rig", "import", src, "--size", "1920x1280", "--projector-size", "1280x800"), 1, src,
                 "--projector-size: expected none", "two cameras and no projector", "found 1280x800")
    zero = _opencv_sample(tmp_path / "zero.yml", T=np.zeros((3, 1)))
    assert_error(cli("rig", "import", zero), 1, zero, "T = (0, 0, 0) mm: a zero stereo baseline")
    with pytest.raises(ConfigError, match=r"T = \(-39.06, 278.3, 61.95\) m: a 288 m stereo baseline; the file "
                                          r"looks like millimetres: use --unit mm"):
        import_rig(_opencv_sample(tmp_path / "neg.yml", T=-T_MM), unit="m")
