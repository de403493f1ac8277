"""``rangekit rig import``: OpenCV stereo calibrations written by cv2.FileStorage, depthai EEPROM JSON and
Horus calibration.json become rig files with the same numbers; ``rig init`` prints matrices on one line."""

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from support.cli_runs import assert_error
from rangekit.cli import main
from rangekit.errors import ConfigError
from rangekit.formats.rig_files.importers import import_rig
from rangekit.rig.rig_file import load_rig

K1 = np.array([[1234.5678901234567, 0.0, 640.123456789], [0.0, 1233.987654321, 401.5], [0.0, 0.0, 1.0]])
D1 = np.array([[-0.123456789012345, 0.0987654321, 1.5e-4, -2.5e-4, 0.01234567]])
K2 = np.array([[1500.25, 0.0, 639.75], [0.0, 1501.125, 399.25], [0.0, 0.0, 1.0]])
D2 = np.array([[0.0312, -0.0456, 3e-5, 4e-5, 0.00123]])
R = cv2.Rodrigues(np.array([[0.0123456789], [-0.3812345678], [0.0234567891]]))[0]
T = np.array([[-0.201234567891], [0.00312345678], [0.0412345678]])


def _write_opencv(path, **extra):
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for k, v in {**dict(K1=K1, D1=D1, K2=K2, D2=D2, R=R, T=T), **extra}.items():
        fs.write(k, v)
    fs.release()


@pytest.mark.parametrize("suffix", [".yaml", ".xml"])
def test_opencv_filestorage_values_come_back_to_1e_12(tmp_path, suffix):
    src = tmp_path / f"stereo{suffix}"
    _write_opencv(src, imageSize=np.array([[1280], [800]], float), projectorSize=np.array([[1920], [1080]], float))
    assert main(["rig", "import", str(src), "--out", str(tmp_path / "rig.json")]) == 0
    rig = load_rig(tmp_path / "rig.json")
    cam, proj = rig.camera, rig.projector
    assert (cam.width, cam.height, proj.width, proj.height) == (1280, 800, 1920, 1080)
    np.testing.assert_allclose(cam.K, K1, rtol=0, atol=1e-12)
    np.testing.assert_allclose(proj.K, K2, rtol=0, atol=1e-12)
    np.testing.assert_allclose(cam.dist, D1.ravel(), rtol=0, atol=1e-12)
    np.testing.assert_allclose(proj.dist, D2.ravel(), rtol=0, atol=1e-12)
    T_proj_cam = np.linalg.inv(rig.projector.T_world_cam) @ rig.camera.T_world_cam     # X_proj = R X_cam + T
    np.testing.assert_allclose(T_proj_cam[:3, :3], R, rtol=0, atol=1e-12)
    np.testing.assert_allclose(T_proj_cam[:3, 3], T.ravel(), rtol=0, atol=1e-12)
    assert np.array_equal(rig.camera.T_world_cam, np.eye(4)) and rig.T_world_table is None


def test_opencv_sizes_units_and_printing(tmp_path, capsys):
    src = tmp_path / "calib.yml"
    _write_opencv(src, T=T * 1000)                          # millimetres
    assert main(["rig", "import", str(src), "--unit", "mm"]) == 1          # no size in the file, none given
    assert ("calib.yml: expected the camera image size (keys imageSize, image_size, cam_size or image_width and "
            "image_height), found none; give it with --size WxH") in capsys.readouterr().err
    assert main(["rig", "import", str(src), "--size", "640x480", "--projector-size", "800x600", "--unit", "mm"]) == 0
    text = capsys.readouterr().out
    data = json.loads(text)
    assert '"K": [[1234.5678901234567, 0.0, 640.123456789], [0.0, 1233.987654321, 401.5], [0.0, 0.0, 1.0]]' in text
    assert (data["cameras"][0]["width"], data["projector"]["height"]) == (640, 600)
    T_world_proj = np.array(data["projector"]["T_world_cam"])
    np.testing.assert_allclose(-R.T @ T.ravel(), T_world_proj[:3, 3], atol=1e-15)


def test_opencv_errors_name_the_file_the_key_and_what_was_found(tmp_path):
    src = tmp_path / "calib.yaml"
    fs = cv2.FileStorage(str(src), cv2.FILE_STORAGE_WRITE)
    fs.write("K1", K1)
    fs.release()
    with pytest.raises(ConfigError, match=r"calib.yaml: expected one of the keys D1, distCoeffs1.*found none; the "
                                          r"file has K1"):
        import_rig(src, size=(640, 480), projector_size=(640, 480))
    _write_opencv(src, imageSize=np.array([[1280.5], [800]]))
    with pytest.raises(ConfigError, match=r"imageSize: expected \[width, height\] in pixels, found \[1280.5, 800"):
        import_rig(src, projector_size=(640, 480))
    bad = tmp_path / "bad.yaml"
    bad.write_text("not: [an, opencv\n")
    with pytest.raises(ConfigError, match="bad.yaml: expected an OpenCV FileStorage file"):
        import_rig(bad)
    with pytest.raises(ConfigError, match=r"calib.txt: expected a calibration file \(.yaml, .yml, .xml, .json\), "
                                          r"found '.txt'"):
        import_rig(tmp_path / "calib.txt")


def _depthai_camera(K, width, height, to, R, t_cm):
    dist = [0.01, -0.02, 0.001, 0.002, 0.003, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]
    return {"cameraType": 0, "distortionCoeff": dist, "height": height, "width": width, "intrinsicMatrix": K,
            "lensPosition": 0, "specHfovDeg": 71.86,
            "extrinsics": {"rotationMatrix": R, "specTranslation": {"x": -7.5, "y": 0.0, "z": 0.0},
                           "toCameraSocket": to, "translation": dict(zip("xyz", t_cm))}}


def test_depthai_eeprom_json_chains_the_extrinsics_into_the_rgb_camera_frame(tmp_path):
    """An OAK-D layout: CAM_B (left) -> CAM_C (right) -> CAM_A (rgb), translations in cm."""
    R_bc = cv2.Rodrigues(np.array([0.001, 0.02, -0.003]))[0]
    R_ca = cv2.Rodrigues(np.array([-0.002, -0.01, 0.004]))[0]
    t_bc, t_ca = [-7.5, 0.01, 0.02], [3.75, -0.02, 0.01]
    I = np.eye(3).tolist()
    data = {"batchName": "", "boardName": "OAK-D", "productName": "OAK-D", "version": 7, "cameraData": [
        [2, _depthai_camera([[800.0, 0, 640.0], [0, 800.0, 400.0], [0, 0, 1]], 1280, 800, 0, R_ca.tolist(), t_ca)],
        [1, _depthai_camera([[801.0, 0, 641.0], [0, 801.0, 401.0], [0, 0, 1]], 1280, 800, 2, R_bc.tolist(), t_bc)],
        [0, _depthai_camera([[3000.0, 0, 1920.0], [0, 3000.0, 1080.0], [0, 0, 1]], 3840, 2160, -1, I, [0, 0, 0])],
    ], "stereoRectificationData": {"leftCameraSocket": 1, "rightCameraSocket": 2}}
    src = tmp_path / "eeprom.json"
    src.write_text(json.dumps(data))
    rig = load_rig_dict(import_rig(src))
    assert [c.name for c in rig.cameras] == ["CAM_A", "CAM_B", "CAM_C"] and rig.projector is None
    T_a_c = np.eye(4)
    T_a_c[:3, :3], T_a_c[:3, 3] = R_ca, np.array(t_ca) / 100
    T_c_b = np.eye(4)
    T_c_b[:3, :3], T_c_b[:3, 3] = R_bc, np.array(t_bc) / 100
    np.testing.assert_allclose(rig.cameras[2].T_world_cam, T_a_c, atol=1e-12)
    np.testing.assert_allclose(rig.cameras[1].T_world_cam, T_a_c @ T_c_b, atol=1e-12)
    assert np.allclose(rig.cameras[0].T_world_cam, np.eye(4)) and rig.cameras[0].width == 3840
    np.testing.assert_allclose(rig.cameras[1].dist, [0.01, -0.02, 0.001, 0.002, 0.003], atol=0)
    data["cameraData"][0][1]["distortionCoeff"] = [0.0] * 5
    src.write_text(json.dumps(data))
    with pytest.raises(ConfigError, match=r"eeprom.json: cameraData\[socket 2\].distortionCoeff: expected 14 "
                                          r"numbers, found 5"):
        import_rig(src)


def test_a_calibration_written_by_depthai_itself_gives_depthais_own_extrinsics(tmp_path):
    """depthai's CalibrationHandler (the library an OAK's EEPROM dump comes from) writes the JSON from known
    values; the imported rig has those intrinsics and, for each camera, the pose depthai itself computes
    (``getCameraExtrinsics(camera, CAM_A)``, cm) in metres. depthai stores float32: 1e-6 relative."""
    dai = pytest.importorskip("depthai")
    A, B, C = dai.CameraBoardSocket.CAM_A, dai.CameraBoardSocket.CAM_B, dai.CameraBoardSocket.CAM_C
    cal = dai.CalibrationHandler()
    K = {A: [[3012.5, 0, 1921.25], [0, 3011.75, 1079.5], [0, 0, 1]],
         B: [[801.5, 0, 641.25], [0, 800.75, 401.5], [0, 0, 1]], C: [[799.25, 0, 639.5], [0, 799.5, 399.25], [0, 0, 1]]}
    size = {A: (3840, 2160), B: (1280, 800), C: (1280, 800)}
    dist = {A: [0.05, -0.1, 0.001, -0.002, 0.02], B: [-0.01, 0.02, 0.0005, 0.0004, -0.003],
            C: [0.015, -0.025, -0.0003, 0.0002, 0.004]}
    for s in (A, B, C):
        cal.setCameraIntrinsics(s, K[s], *size[s])
        cal.setDistortionCoefficients(s, dist[s] + [0.0] * 9)
    R_bc = cv2.Rodrigues(np.array([0.001, 0.02, -0.003]))[0]
    R_ca = cv2.Rodrigues(np.array([-0.002, -0.01, 0.004]))[0]
    cal.setCameraExtrinsics(B, C, R_bc.tolist(), [-7.5, 0.01, 0.02], [-7.5, 0, 0])
    cal.setCameraExtrinsics(C, A, R_ca.tolist(), [3.75, -0.02, 0.01], [3.75, 0, 0])
    cal.setStereoLeft(B, np.eye(3).tolist())
    cal.setStereoRight(C, np.eye(3).tolist())
    src = tmp_path / "eeprom.json"
    cal.eepromToJsonFile(str(src))
    rig = load_rig_dict(import_rig(src))
    cams = {c.name: c for c in rig.cameras}
    assert set(cams) == {"CAM_A", "CAM_B", "CAM_C"} and rig.projector is None
    for name, s in (("CAM_A", A), ("CAM_B", B), ("CAM_C", C)):
        cam = cams[name]
        assert (cam.width, cam.height) == size[s]
        np.testing.assert_allclose(cam.K, K[s], rtol=1e-6)
        np.testing.assert_allclose(cam.dist, dist[s], rtol=1e-6, atol=1e-9)
        T_dai = np.array(cal.getCameraExtrinsics(s, A), float)       # camera -> CAM_A, translation in cm
        T_dai[:3, 3] /= 100
        np.testing.assert_allclose(cam.T_world_cam, T_dai, atol=1e-6)
    data = json.loads(src.read_text())                       # a rotation that is not one is refused by name
    data["cameraData"][1][1]["extrinsics"]["rotationMatrix"][0][0] *= 1.01
    src.write_text(json.dumps(data))
    with pytest.raises(ConfigError, match=r"eeprom.json: cameraData\[1\].extrinsics.rotationMatrix: expected a "
                                          r"rotation \(orthonormal, det \+1\), found max \|R R\^T - I\| = 0.02"):
        import_rig(src)


def load_rig_dict(data):
    from rangekit.rig.rig_file import Rig

    return Rig.from_dict(data)


def test_horus_calibration_json_gives_camera_lasers_and_turntable(tmp_path):
    """Horus's profile layout: calibration_settings, each value under "value"; millimetres."""
    K = [[1430.0, 0.0, 480.0], [0.0, 1430.0, 620.0], [0.0, 0.0, 1.0]]
    Rp = cv2.Rodrigues(np.array([1.5, 0.01, -0.02]))[0]
    tp = [5.0, 80.0, 320.0]
    nl = np.array([0.86, 0.0, 0.51]) / np.linalg.norm([0.86, 0.0, 0.51])
    settings = {"camera_matrix": K, "distortion_vector": [0.1, -0.2, 0.0, 0.001, 0.3],
                "distance_left": 160.5, "normal_left": nl.tolist(), "distance_right": 158.25,
                "normal_right": [-0.85, 0.01, 0.52], "rotation_matrix": Rp.tolist(), "translation_vector": tp}
    src = tmp_path / "calibration.json"
    src.write_text(json.dumps({"calibration_settings": {k: {"value": v} for k, v in settings.items()}}))
    with pytest.raises(ConfigError, match=r"calibration.json: expected the camera's image size \(camera_width, "
                                          r"camera_height\), found none; give it with --size WxH"):
        import_rig(src)
    assert main(["rig", "import", str(src), "--size", "960x1280", "--out", str(tmp_path / "rig.json")]) == 0
    # Horus's own camera settings, as its profile writes them (checked against Horus's Settings.save_settings):
    # the capture size, transposed when camera_rotate is on (its default).
    camera = {"camera_width": {"max_value": 10000, "min_value": 1, "value": 1280},
              "camera_height": {"max_value": 10000, "min_value": 1, "value": 960},
              "camera_rotate": {"value": True}, "camera_hflip": {"value": True}, "camera_vflip": {"value": False}}
    doc = {"settings_version": "0.2", "calibration_settings": {**{k: {"value": v} for k, v in settings.items()},
                                                                **camera}}
    src.write_text(json.dumps(doc))
    assert load_rig_dict(import_rig(src)).camera.width == 960 and load_rig_dict(import_rig(src)).camera.height == 1280
    doc["calibration_settings"]["camera_rotate"]["value"] = False
    src.write_text(json.dumps(doc))
    assert (load_rig_dict(import_rig(src)).camera.width, load_rig_dict(import_rig(src)).camera.height) == (1280, 960)
    rig = load_rig(tmp_path / "rig.json")
    np.testing.assert_allclose(rig.camera.K, K, atol=0)
    np.testing.assert_allclose(rig.T_world_table[:3, :3], Rp, atol=1e-15)
    np.testing.assert_allclose(rig.T_world_table[:3, 3], np.array(tp) / 1000, atol=1e-15)
    left = rig.lasers[0]
    X = nl * 0.1605                                  # a point of n . X = d (mm -> m)
    assert abs(left.plane[:3] @ X + left.plane[3]) < 1e-12 and left.plane[3] > 0   # camera-side normal
    del settings["normal_right"]
    src.write_text(json.dumps(settings))             # the flat layout too
    with pytest.raises(ConfigError, match="calibration.json: normal_right: expected it"):
        import_rig(src, size=(960, 1280))


def test_rig_init_prints_each_matrix_on_one_line(capsys):
    assert main(["rig", "init"]) == 0
    text = capsys.readouterr().out
    assert '      "K": [[1000.0, 0.0, 639.5], [0.0, 1000.0, 399.5], [0.0, 0.0, 1.0]],\n' in text
    assert json.loads(text)["cameras"][0]["K"][2] == [0.0, 0.0, 1.0]


# --------------------------------------------------------------------------- structured-light tools' files


def _slstudio_xml(path, *, Rp=None, drop=()):
    """A calibration.xml with SLStudio's keys (float32 matrices, millimetres), as its calibrator writes it."""
    import cv2

    R = cv2.Rodrigues(np.array([[0.15], [-0.23], [0.14]]))[0] if Rp is None else np.asarray(Rp)
    values = {"Kc": np.array([[2195.1, 0, 843.5], [0, 2195.1, 675.5], [0, 0, 1]], np.float32),
              "kc": np.array([[-0.058], [0], [0], [0], [0]], np.float32),
              "Kp": np.array([[2601.5, 0, 866.5], [0, 2601.5, 1109.1], [0, 0, 1]], np.float32),
              "kp": np.array([[-0.031], [0], [0], [0], [0]], np.float32),
              "Rp": R.astype(np.float32), "Tp": np.array([[-145.28], [-36.50], [67.92]], np.float32)}
    fs = cv2.FileStorage(str(path), cv2.FILE_STORAGE_WRITE)
    for k, v in values.items():
        if k not in drop:
            fs.write(k, v)
    for k, v in (("frameWidth", 1688), ("frameHeight", 1352), ("screenResX", 1824), ("screenResY", 1140)):
        if k not in drop:
            fs.write(k, v)
    fs.release()
    return values


def test_slstudio_calibration_reads_its_keys_units_and_convention(cli, tmp_path):
    values = _slstudio_xml(tmp_path / "calibration.xml")
    run = cli("rig", "import", tmp_path / "calibration.xml", "--out", tmp_path / "rig.json")
    assert run.code == 0, run.err
    rig = load_rig(tmp_path / "rig.json")
    cam, proj = rig.cameras[0], rig.projector
    assert (cam.width, cam.height, proj.width, proj.height) == (1688, 1352, 1824, 1140)
    np.testing.assert_allclose(cam.K, values["Kc"], rtol=1e-6)
    np.testing.assert_allclose(proj.K, values["Kp"], rtol=1e-6)
    # X_proj = Rp X_cam + Tp (mm): the projector's centre in the camera frame is -Rp^T Tp, in metres.
    centre = -values["Rp"].astype(float).T @ values["Tp"].astype(float).ravel() / 1000
    np.testing.assert_allclose(proj.T_world_cam[:3, 3], centre, atol=1e-6)
    assert np.allclose(cam.T_world_cam, np.eye(4))


def test_slstudio_calibration_with_a_bad_rotation_or_a_missing_size_is_named(cli, tmp_path):
    _slstudio_xml(tmp_path / "a.xml", Rp=np.diag([1.0, 1.0, 2.0]))
    run = cli("rig", "import", tmp_path / "a.xml", "--out", tmp_path / "a.json")
    assert_error(run, 1, "a.xml", "Rp: expected a 3x3 rotation")
    _slstudio_xml(tmp_path / "b.xml", drop=("screenResX",))
    run = cli("rig", "import", tmp_path / "b.xml", "--out", tmp_path / "b.json")
    assert_error(run, 1, "b.xml", "screenResX/screenResY", "width and a height")


def test_slstudios_own_calibration_file_imports(cli, tmp_path):
    from support.shared_data import require_shared

    run = cli("rig", "import", require_shared("slstudio-skull", "calibration", "calibration.xml"), "--out", tmp_path / "rig.json")
    assert run.code == 0, run.err
    rig = load_rig(tmp_path / "rig.json")
    assert rig.cameras[0].K[0, 0] == pytest.approx(2195.12036, rel=1e-6)
    assert np.linalg.norm(rig.projector.T_world_cam[:3, 3]) == pytest.approx(0.164477, abs=1e-5)   # |Tp| = 164.5 mm


@pytest.mark.parametrize("change, size, mentions", [
    (lambda K: K * np.array([[1e-12, 1, 1], [1, 1e-12, 1], [1, 1, 1]]), "1280x800", ["fx = 1.23457e-09 px"]),
    (lambda K: K * np.array([[1e12, 1, 1], [1, 1e12, 1], [1, 1, 1]]), "1280x800", ["fx = 1.23457e+15 px"]),
    (lambda K: K + np.array([[0, 0, -5640.0], [0, 0, 0], [0, 0, 0]]), "1280x800", ["cx = -4999.88 px"]),
    (lambda K: K, "1x1", ["an image of 1x1 pixels"]),
], ids=["focal_1e-9", "focal_1e15", "principal_point", "one_pixel"])
def test_implausible_intrinsics_are_refused_by_one_rule(tmp_path, change, size, mentions):
    """Issue 48: rig import took a focal length of 1e-9 or 1e15 px, a principal point of -5000 px for a 1280-px
    image and a 1x1 image without a word; the rig file's one plausibility rule (rangekit.rig.plausibility) refuses
    each, naming the value and the range, for every import and every rig file."""
    src = tmp_path / "calib.yaml"
    _write_opencv(src, K1=change(K1))
    run_args = ["rig", "import", str(src), "--size", size, "--projector-size", "1280x800", "--out",
                str(tmp_path / "rig.json")]
    with pytest.raises(ConfigError, match="implausible intrinsics") as refused:
        import_rig(src, size=tuple(int(v) for v in size.split("x")), projector_size=(1280, 800))
    for text in mentions:
        assert text in str(refused.value)
    if size != "1x1":                               # --size 1x1 itself is refused as an option (the test below)
        assert main(run_args) == 1 and not (tmp_path / "rig.json").exists()


@pytest.mark.parametrize("suffix", [".yaml", ".xml"])
def test_a_key_given_twice_is_refused(tmp_path, suffix):
    src = tmp_path / f"calib{suffix}"
    _write_opencv(src)
    text = src.read_text()
    if suffix == ".xml":
        text = text.replace("</opencv_storage>", "<T>1.0</T>\n</opencv_storage>")
    else:
        text += "T: 1.0\n"
    src.write_text(text)
    with pytest.raises(ConfigError, match="expected each key once, found 'T' given more than once"):
        import_rig(src, size=(1280, 800), projector_size=(1280, 800))


@pytest.mark.parametrize("preset", ["slstudio:2x3", "slstudio:micro", "opencv:graycode"])
def test_a_one_pixel_projector_is_refused_for_every_preset(cli, tmp_path, preset):
    """Issue 48: ``decode --pattern slstudio:2x3 --projector 1x1`` wrote maps (micro too); the option's size rule is
    the rig file's (at least 8 pixels a side), for every preset."""
    run = cli("decode", tmp_path, "--pattern", preset, "--projector", "1x1", "--out", tmp_path / "m.npz")
    assert_error(run, 2, "--projector", "each 8..")
    assert not (tmp_path / "m.npz").exists()
