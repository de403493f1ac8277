"""``rangekit rig import`` of RoomAlive's ProjectorCameraEnsemble XML (rangekit/formats/rig_files/roomalive.py),
written here in RoomAlive's layout (XmlSerializer, matrices by column) from known values. Every number comes back,
and a point projects where RoomAlive's own model (CameraMath.Project, Kinect2Calibration's ``H - v``,
CalibrateProjectorGroups' ``width - u``) puts it, in the flipped Kinect images: a transpose, an inverse, a sign
or a flip fails."""

import cv2
import numpy as np
import pytest

from support.cli_runs import assert_error
from rangekit.formats.rig_files.importers import import_rig
from rangekit.geometry import apply_T, invert_T, make_T
from rangekit.rig.rig_file import Rig
from rangekit.sim.scene.zoo import data_folders

K_COLOUR = np.array([[1060.55, 0.0, 947.61], [0.0, 1061.62, 562.16], [0.0, 0.0, 1.0]])
K_DEPTH = np.array([[369.19, 0.0, 262.89], [0.0, 368.22, 217.72], [0.0, 0.0, 1.0]])
K_PROJ = np.array([[2070.04, 0.0, 686.04], [0.0, 2071.5, 163.14], [0.0, 0.0, 1.0]])
D_COLOUR, D_DEPTH, D_PROJ = (0.0145, -0.00162), (0.0455, -0.1537), (0.012, -0.003)
DEPTH_TO_COLOUR = make_T(cv2.Rodrigues(np.array([0.003, -0.0005, 0.0095]))[0], [0.0527, 1.5e-5, -1.5e-5])
CAMERA_POSE = make_T(cv2.Rodrigues(np.array([0.02, 0.1, -0.03]))[0], [0.3, -0.2, 0.1])
PROJECTOR_POSE = make_T(cv2.Rodrigues(np.array([0.14, 0.15, 0.01]))[0], [-0.03, -0.08, 0.06])
SIZE = (1400, 1050)


def _matrix(name, m, indent="      "):
    m = np.atleast_2d(np.asarray(m, dtype=float))
    columns = "".join(f"{indent}    <ArrayOfDouble>\n" + "".join(f"{indent}      <double>{float(v)!r}</double>\n" for v in col)
                      + f"{indent}    </ArrayOfDouble>\n" for col in m.T)
    return f"{indent}<{name}>\n{indent}  <ValuesByColumn>\n{columns}{indent}  </ValuesByColumn>\n{indent}</{name}>\n"


def _ensemble(path, *, calibrated=True, cameras=1, projector_pose=PROJECTOR_POSE):
    """An ensemble as RoomAlive's ProjectorCameraEnsemble.Save writes it (``calibrated`` False: as its New dialog
    leaves it, calibration2.xml's content)."""
    calibration = ("      <calibration>\n" + "".join(_matrix(n, m, "        ") for n, m in (
        ("colorCameraMatrix", K_COLOUR), ("colorLensDistortion", np.array([D_COLOUR]).T),
        ("depthCameraMatrix", K_DEPTH), ("depthLensDistortion", np.array([D_DEPTH]).T),
        ("depthToColorTransform", DEPTH_TO_COLOUR))) + "      </calibration>\n") if calibrated else ""
    camera = ("    <Camera>\n      <name>0</name>\n      <hostNameOrAddress>localhost</hostNameOrAddress>\n"
              + _matrix("pose", CAMERA_POSE) + calibration + "    </Camera>\n")
    w, h = SIZE if calibrated else (0, 0)
    projector = ("    <Projector>\n      <name>0</name>\n      <hostNameOrAddress>localhost</hostNameOrAddress>\n"
                 f"      <displayIndex>1</displayIndex>\n      <width>{w}</width>\n      <height>{h}</height>\n"
                 + ((_matrix("cameraMatrix", K_PROJ) + _matrix("lensDistortion", np.array([D_PROJ]).T)
                     + _matrix("pose", projector_pose)) if calibrated else "") + "    </Projector>\n")
    path.write_text('<?xml version="1.0" encoding="utf-8"?>\n<ProjectorCameraEnsemble xmlns:xsd="http://www.w3.org/'
                    '2001/XMLSchema" xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance">\n  <name>Untitled</name>\n'
                    f"  <cameras>\n{camera * cameras}  </cameras>\n  <projectors>\n{projector}  </projectors>\n"
                    "</ProjectorCameraEnsemble>\n", encoding="utf-8")
    return path


def _ra_project(K, d, P):
    """RoomAlive's CameraMath.Project: radial k1, k2 on X / Z, Y / Z."""
    x, y = P[:, 0] / P[:, 2], P[:, 1] / P[:, 2]
    r2 = x * x + y * y
    f = 1 + d[0] * r2 + d[1] * r2 * r2
    return np.column_stack([K[0, 0] * x * f + K[0, 2], K[1, 1] * y * f + K[1, 2]])


def test_every_number_of_an_ensemble_comes_back(tmp_path):
    rig = Rig.from_dict(import_rig(_ensemble(tmp_path / "ensemble.xml")))
    colour, depth = rig.cameras
    assert (colour.name, colour.size, depth.name, depth.size) == ("kinect_colour", (1920, 1080), "kinect_depth",
                                                                 (512, 424))
    assert rig.projector.size == SIZE and rig.T_world_table is None
    np.testing.assert_allclose(colour.K, [[1060.55, 0, 1919 - 947.61], [0, 1061.62, 1080 - 562.16], [0, 0, 1]])
    np.testing.assert_allclose(depth.K, [[369.19, 0, 511 - 262.89], [0, 368.22, 424 - 217.72], [0, 0, 1]])
    np.testing.assert_allclose(rig.projector.K, [[2070.04, 0, 1400 - 686.04], [0, 2071.5, 1050 - 163.14], [0, 0, 1]])
    for cam, d in ((colour, D_COLOUR), (depth, D_DEPTH), (rig.projector, D_PROJ)):
        np.testing.assert_allclose(cam.dist, [*d, 0, 0, 0])
    np.testing.assert_allclose(colour.T_world_cam, np.eye(4))
    N = np.diag([-1.0, -1, 1, 1])
    np.testing.assert_allclose(depth.T_world_cam, N @ DEPTH_TO_COLOUR @ N, atol=1e-12)
    np.testing.assert_allclose(rig.projector.T_world_cam,
                               N @ DEPTH_TO_COLOUR @ invert_T(CAMERA_POSE) @ PROJECTOR_POSE @ N, atol=1e-12)


def test_points_land_where_roomalive_puts_them(tmp_path):
    """Depth camera points (RoomAlive's frame) seen by RoomAlive's model and by the imported rig: the colour pixel
    is RoomAlive's (u, 1080 - v) flipped left to right, the depth pixel (u, 424 - v) likewise, the projector's
    decoded column and row (1400 - u, 1050 - v)."""
    rig = Rig.from_dict(import_rig(_ensemble(tmp_path / "ensemble.xml")))
    colour, depth = rig.cameras
    rng = np.random.default_rng(1)
    P_depth = np.column_stack([rng.uniform(-1, 1, 50), rng.uniform(-0.6, 0.6, 50), rng.uniform(2, 4, 50)])
    P_colour = apply_T(DEPTH_TO_COLOUR, P_depth)
    P_proj = apply_T(invert_T(PROJECTOR_POSE) @ CAMERA_POSE, P_depth)
    world = apply_T(depth.T_world_cam, P_depth * [-1, -1, 1])      # RoomAlive's depth frame -> OpenCV's -> world
    uv = _ra_project(K_COLOUR, D_COLOUR, P_colour)
    np.testing.assert_allclose(colour.project(world), np.column_stack([1919 - uv[:, 0], 1080 - uv[:, 1]]), atol=1e-6)
    uv = _ra_project(K_DEPTH, D_DEPTH, P_depth)
    np.testing.assert_allclose(depth.project(world), np.column_stack([511 - uv[:, 0], 424 - uv[:, 1]]), atol=1e-6)
    uv = _ra_project(K_PROJ, D_PROJ, P_proj)
    np.testing.assert_allclose(rig.projector.project(world), np.column_stack([1400 - uv[:, 0], 1050 - uv[:, 1]]),
                               atol=1e-6)


def test_an_ensemble_not_yet_calibrated_is_refused_in_one_line(cli, tmp_path):
    path = _ensemble(tmp_path / "calibration2.xml", calibrated=False)
    line = assert_error(cli("rig", "import", path, "--out", tmp_path / "rig.json"), 1, "calibration2.xml",
                        "expected a calibrated ensemble", "0x0 projector", "before RoomAlive's Acquire and Calibrate")
    assert "\n" not in line


def test_two_cameras_and_a_pose_written_by_rows_are_refused(tmp_path):
    from rangekit.errors import ConfigError

    with pytest.raises(ConfigError, match=r"one camera and one projector .*found 2 camera"):
        import_rig(_ensemble(tmp_path / "two.xml", cameras=2))
    with pytest.raises(ConfigError, match="projectors/Projector/pose: expected a 4x4 rigid transform"):
        import_rig(_ensemble(tmp_path / "rows.xml", projector_pose=PROJECTOR_POSE.T))


def _roomalive_folder():
    folder = next((f / "roomalive" / "calibration" for f in data_folders()
                   if (f / "roomalive" / "calibration" / "07181614.xml").is_file()), None)
    if folder is None:
        pytest.skip(f"roomalive/calibration is not in {[str(f) for f in data_folders()]}")
    return folder


@pytest.mark.slow
def test_roomalives_own_ensembles_import(cli, tmp_path):
    folder = _roomalive_folder()
    run = cli("rig", "import", folder / "07181614.xml", "--out", tmp_path / "rig.json")
    assert run.code == 0, run.err
    rig = Rig.from_dict(import_rig(folder / "07181614.xml"))
    assert rig.cameras[0].K[0, 0] == pytest.approx(1060.548322335942)
    assert rig.projector.K[0, 0] == pytest.approx(2070.040483324141)
    assert np.linalg.norm(rig.cameras[1].T_world_cam[:3, 3]) == pytest.approx(0.0527, abs=1e-4)   # depth-colour
    assert np.linalg.norm(rig.projector.T_world_cam[:3, 3]) == pytest.approx(0.1051, abs=1e-3)    # the projector
    assert_error(cli("rig", "import", folder / "calibration2.xml", "--out", tmp_path / "r2.json"), 1,
                 "calibration2.xml", "expected a calibrated ensemble")
