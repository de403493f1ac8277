"""Calibration boards against the simulator's ground truth: texture, area sampling, detection, poses."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from rangekit.boards import Board, _orient_grid, detect_board
from rangekit.camera import PinholeCamera
from rangekit.errors import InputError, SceneError
from rangekit.geometry import R_to_quat, apply_T, axis_angle_to_R, compose, make_T
from rangekit.sim import Scene, SimRig, cast_view, default_rig, default_scene
from rangekit.sim.writers.calibration import board_poses, board_scene, turntable_board_scene
from rangekit.sim.scene.objects import board_object

WHITE = np.full((800, 1280), 255, np.uint8)


@pytest.fixture(scope="module")
def sim():
    """One full-resolution default rig (its ray caches are shared by every render in this file)."""
    return SimRig(board_scene(Board(), make_T(t=[0, 0, 0.06])), default_rig())


@pytest.fixture(scope="module")
def small_rig():
    """The default rig with the camera at half resolution (same field of view), for quick renders."""
    rig = default_rig()
    return dataclasses.replace(rig, cameras=(rig.camera.resized(640, 512),))


def _errors(sim: SimRig, board: Board, poses: list[np.ndarray]):
    """Render each pose under white light, detect, and return per-corner pixel errors vs the truth."""
    errs, counts = [], []
    for T in poses:
        sim.set_scene(board_scene(board, T))
        det = detect_board(sim.capture_sequence([WHITE])[0], board)
        assert det.found, det.reason
        truth = sim.rig.camera.project(apply_T(T, board.object_points()))
        errs.append(np.linalg.norm(det.uv - truth[det.ids], axis=1))
        counts.append(len(det.ids))
    return np.concatenate(errs), counts


# --- board geometry ----------------------------------------------------------------------------------

def test_board_frame_matches_opencv_charuco_and_texture():
    b = Board("charuco")
    k = b.object_points()
    assert k.shape == (54, 3) and k.dtype == np.float64
    assert np.allclose(k[[0, 1, 9, 53]], [[0, 0, 0], [0.02, 0, 0], [0, 0.02, 0], [0.16, 0.10, 0]])
    # OpenCV's ChArUco corner k, shifted by -square, is our corner k
    cv_corners = np.array(b.opencv_board().getChessboardCorners(), np.float64)
    assert np.abs(cv_corners - [b.square, b.square, 0] - k).max() < 1e-8
    img, (x0, y0, x1, y1) = b.texture(1e-4)
    assert img.dtype == np.float32 and img.shape == (1600, 2200)
    assert np.allclose([x0, y0, x1, y1], b.extent, atol=1e-15)
    # squares: sample the corner regions of each square (outside any marker); dark where (r + c) even
    r, c = np.divmod(np.arange(b.rows * b.cols), b.cols)
    x = (c - 1) * b.square + 0.0005
    y = (r - 1) * b.square + 0.0005
    vals = img[np.floor((y - y0) / 1e-4).astype(int), np.floor((x - x0) / 1e-4).astype(int)]
    assert np.all(vals == np.where((r + c) % 2 == 0, np.float32(b.dark), np.float32(b.light)))
    # square edges on texel boundaries: the texel either side of x = 0 changes colour along row 0's squares
    row = img[int(round((-0.01 - y0) / 1e-4)), :]
    j0 = int(round((0.0 - x0) / 1e-4))
    assert row[j0 - 1] == np.float32(b.dark) and row[j0] == np.float32(b.light)
    assert set(np.unique(img)) == {np.float32(b.dark), np.float32(b.light)}
    # the checkerboard texture is the same grid without markers, dark square at (-x, -y)
    cb, _ = Board().texture()
    assert cb[150, 150] == np.float32(0.05) and cb[150, 350] == np.float32(0.9)


def test_board_validation_names_the_field():
    for kwargs, field in [(dict(kind="circles"), "kind"), (dict(cols=1), "cols"), (dict(rows=2.5), "rows"),
                          (dict(square=0.0), "square"), (dict(marker=0.03), "marker"), (dict(margin=-1e-3), "margin"),
                          (dict(dark=0.9, light=0.5), "dark"), (dict(dictionary="DICT_NOPE"), "dictionary")]:
        with pytest.raises(InputError, match=field):
            Board(**kwargs)
    with pytest.raises(InputError, match="DICT_4X4_50 has 50"):
        Board("charuco", cols=12, rows=9, dictionary="DICT_4X4_50")
    with pytest.raises(InputError, match="whole number of texels.*texel="):
        Board().texture(3e-4)


# --- simulator texture -------------------------------------------------------------------------------

def test_texture_is_area_sampled_over_the_pixel_footprint():
    # Undistorted camera at the origin looking along +z; the board fronto-parallel at 0.5 m, printed side
    # towards the camera. A pixel spans 0.5 mm = 5 texels; the board's x = 0 edge splits pixel column 32
    # 30 % / 70 %, and its y = 0 edge splits pixel row 24 60 % / 40 %.
    f, z = 1000.0, 0.5
    cam = PinholeCamera(K=[[f, 0, 31.5], [0, f, 23.5], [0, 0, 1]], width=64, height=48, dist=np.zeros(5))
    pix = z / f
    board = Board()
    T = make_T(t=[(32 - 31.5 - 0.5 + 0.3) * pix, (24 - 23.5 - 0.5 + 0.6) * pix, z])
    geom = cast_view(Scene((board_object(board).with_pose(T),)).world_mesh(), cam, None)
    albedo = geom.albedo[..., 0]
    dark, light = board.dark, board.light
    # Row 14 sees square row 0 (y in [-2 cm, 0]): dark for x < 0, light for 0 < x < 2 cm.
    u = np.arange(20, 45)
    frac_dark = np.clip((32 - 0.5 + 0.3 - (u - 0.5)), 0, 1)  # pixel u covers [u - 0.5, u + 0.5]; edge at 31.8
    assert np.abs(albedo[14, u] - (frac_dark * dark + (1 - frac_dark) * light)).max() < 1e-3
    assert abs(albedo[14, 32] - (0.3 * dark + 0.7 * light)) < 1e-3
    # The pixel holding corner 0 (x = y = 0): four quadrants, dark at (-x, -y) and (+x, +y).
    a, b = 0.3, 0.6
    expected = (a * b + (1 - a) * (1 - b)) * dark + (a * (1 - b) + (1 - a) * b) * light
    assert abs(albedo[24, 32] - expected) < 1e-3
    # Seen from behind (board turned 180 deg about its y axis) the board is plain: its vertex albedo.
    back = T @ make_T(axis_angle_to_R([0, 1, 0], np.pi), [0.08, 0, 0])
    geom = cast_view(Scene((board_object(board).with_pose(back),)).world_mesh(), cam, None)
    assert np.allclose(geom.albedo[geom.hit][:, 0], board_object(board).vertex_albedo[0, 0])


def test_set_scene_reproducible_and_new_noise_per_scene(small_rig):
    board = Board()
    poses = board_poses(small_rig, board, 2, seed=3)
    a = SimRig(board_scene(board, poses[0]), small_rig, seed=5)
    b = SimRig(board_scene(board, poses[0]), small_rig, seed=5)
    first = [a.capture_sequence([WHITE])[0]]
    a.set_scene(board_scene(board, poses[1]))
    first.append(a.capture_sequence([WHITE])[0])
    a.set_scene(board_scene(board, poses[0]))  # back to the first pose: same geometry, new noise
    first.append(a.capture_sequence([WHITE])[0])
    second = [b.capture_sequence([WHITE])[0]]
    b.scene = board_scene(board, poses[1])  # assignment is set_scene
    second.append(b.capture_sequence([WHITE])[0])
    b.set_scene(board_scene(board, poses[0]))
    second.append(b.capture_sequence([WHITE])[0])
    assert all(np.array_equal(x, y) for x, y in zip(first, second))
    assert not np.array_equal(first[0], first[2])
    # same scene, same expected image: only the noise differs (and the geometry cache was dropped)
    diff = first[0].astype(int) - first[2].astype(int)
    assert 0 < np.abs(diff).mean() < 3
    assert not np.array_equal(first[0], first[1])
    with pytest.raises(SceneError, match="Scene"):
        a.set_scene("board")


# --- detection ---------------------------------------------------------------------------------------

@pytest.mark.slow
def test_checkerboard_detection_accuracy(sim):
    board = Board()
    err, counts = _errors(sim, board, board_poses(sim.rig, board, 8, seed=0))
    rms = float(np.sqrt(np.mean(err ** 2)))
    print(f"\ncheckerboard, 8 poses x 54 corners: RMS {rms:.4f} px, max {err.max():.4f} px")
    assert counts == [54] * 8
    assert rms <= 0.032 and err.max() <= 0.07  # measured: RMS 0.0245 px, max 0.0505 px (8 poses)


@pytest.mark.slow
def test_charuco_detection_accuracy(sim):
    board = Board("charuco")
    err, counts = _errors(sim, board, board_poses(sim.rig, board, 10, seed=1))
    rms = float(np.sqrt(np.mean(err ** 2)))
    print(f"\nChArUco, 10 poses: {sum(counts)} corners, RMS {rms:.4f} px, max {err.max():.4f} px")
    assert counts == [54] * 10
    assert rms <= 0.038 and err.max() <= 0.1  # measured: RMS 0.0307 px, max 0.0786 px


@pytest.mark.parametrize("kind", ["checkerboard", "charuco"])
def test_ids_follow_the_board_under_in_plane_rotations(small_rig, kind):
    board = Board(kind)
    cam = small_rig.camera
    sim = SimRig(board_scene(board, np.eye(4)), small_rig)
    x0, y0, x1, y1 = board.extent
    centre = np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.0])
    _, ray = cam.rays(np.array([[cam.K[0, 2], cam.K[1, 2] - 30]]))
    for quarter in range(4):
        # fronto-parallel to the camera, tilted 15 deg about x, turned by quarter * 90 deg in its plane
        R = cam.T_world_cam[:3, :3] @ axis_angle_to_R([1, 0, 0], np.radians(15)) \
            @ axis_angle_to_R([0, 0, 1], quarter * np.pi / 2)
        T = make_T(R, cam.center + 0.6 * ray[0] - R @ centre)
        sim.set_scene(board_scene(board, T))
        image = sim.capture_sequence([WHITE])[0]
        det = detect_board(image, board)
        assert det.found, (quarter, det.reason)
        truth = cam.project(apply_T(T, board.object_points()))[det.ids]
        if quarter == 0:  # RGB and 16-bit captures give the same corners
            rgb = detect_board(np.repeat(image[:, :, None], 3, axis=2), board)
            deep = detect_board(image.astype(np.uint16) * 257, board)
            assert np.array_equal(rgb.ids, det.ids) and np.abs(rgb.uv - det.uv).max() < 1e-3
            assert np.array_equal(deep.ids, det.ids) and np.abs(deep.uv - det.uv).max() < 1e-3
        if kind == "checkerboard":
            # OpenCV may list the grid from any end, or column by column: every reading maps back to the ids
            g = truth.reshape(6, 9, 2)
            for reading in (g, g[::-1, ::-1], g[::-1], g[:, ::-1], g.swapaxes(0, 1), g[::-1, ::-1].swapaxes(0, 1)):
                assert np.array_equal(_orient_grid(reading.reshape(-1, 2), image.astype(np.float32), board), truth)
        # half resolution: corners 30 px apart, so a wrong id would be >= 25 px off
        assert len(det.ids) == 54 and np.linalg.norm(det.uv - truth, axis=1).max() < 0.3, quarter


def test_not_found_gives_a_reason():
    blank = np.full((480, 640), 128, np.uint8)
    for kind in ("checkerboard", "charuco"):
        det = detect_board(blank, Board(kind))
        assert not det.found and "board not found" in det.reason and det.uv.shape == (0, 2)
        assert det.image_size == (640, 480)
    # a ChArUco board seen only in part: fewer corners than asked for
    img, _ = Board("charuco").texture(2e-4)  # 100 px squares, orthographic view
    crop = (np.asarray(img)[:260, :360] * 255).astype(np.uint8)  # about 2 x 3 squares around corner 0
    det = detect_board(np.pad(crop, 40, constant_values=230), Board("charuco"), min_corners=10)
    assert not det.found and det.reason.startswith("only ") and "of 54 corners" in det.reason
    with pytest.raises(InputError, match="180 degree turn"):
        detect_board(blank, Board(cols=9, rows=7))
    with pytest.raises(InputError, match="dtype"):
        detect_board(blank.astype(np.float32), Board())


def test_a_symmetric_checkerboard_is_found_up_to_a_half_turn():
    """rows + cols even (SLStudio's 9 x 13 corners): refused unless asked for; then found in any quarter turn,
    corner 0 the top-left one of the two a half turn swaps; read with cols and rows the wrong way round, its
    dark squares are where the board's light ones are and no orientation fits."""
    board = Board(cols=8, rows=6, square=0.01)
    img, _ = board.texture(2e-4)                                      # 50 px squares, seen square on
    image = np.pad((np.asarray(img) * 255).astype(np.uint8), 40, constant_values=230)
    with pytest.raises(InputError, match="180 degree turn"):
        detect_board(image, board)
    for turns in range(4):
        det = detect_board(np.ascontiguousarray(np.rot90(image, turns)), board, symmetric_ok=True)
        assert det.found and len(det.ids) == 35
        assert det.uv[0].sum() < det.uv[-1].sum()
        step = np.linalg.norm(det.uv[1] - det.uv[0])
        assert abs(step - 50) < 0.5                                    # neighbours along board x
    det = detect_board(image, Board(cols=6, rows=8, square=0.01), symmetric_ok=True)
    assert not det.found and "orientation could not be resolved" in det.reason


def test_a_board_with_an_odd_side_is_found_either_way_round_in_its_own_frame():
    """A 7 x 10 print (rows + cols odd: rangekit's own boards, ``rangekit calibrate`` on hardware) given as 10 x 7:
    found under the reading as given, a quarter turn from the print's frame; each corner's board point is the
    same physical point, so the corners fit the board by the same homography up to that turn."""
    printed, given = Board(cols=7, rows=10, square=0.01), Board(cols=10, rows=7, square=0.01)
    img, _ = printed.texture(2e-4)
    lit = np.pad((np.asarray(img) * 255).astype(np.uint8), 40, constant_values=230)
    for board in (printed, given):
        det = detect_board(lit, board)
        assert det.found and len(det.ids) == 54
        H, _ = cv2.findHomography(board.object_points()[det.ids, :2], det.uv, 0)
        fit = cv2.perspectiveTransform(board.object_points()[None, det.ids, :2], H)[0]
        assert np.abs(fit - det.uv).max() < 0.05                         # a grid of the right size, in order
        assert np.linalg.det(H[:2, :2]) > 0                              # seen from the printed side


# --- poses -------------------------------------------------------------------------------------------

def _twist_about_z(R: np.ndarray) -> float:
    """In-plane angle of R = swing (axis in the x-y plane) @ twist (about z), radians."""
    x, y, z, w = R_to_quat(R)
    return 2 * np.arctan2(z, w)


def test_board_poses_meet_their_constraints():
    rig = default_rig()
    board = Board()
    poses = board_poses(rig, board, 15, seed=0)
    assert len(poses) == 15 and all(np.array_equal(p, q) for p, q in zip(poses, board_poses(rig, board, 15)))
    x0, y0, x1, y1 = board.extent
    corners = np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0]])
    edge = np.concatenate([corners[k] + np.linspace(0, 1, 50)[:, None] * (corners[(k + 1) % 4] - corners[k])
                           for k in range(4)])
    pts = np.concatenate([edge, board.object_points()])
    centre = np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.0])
    cam = rig.camera
    centres_uv, tilts, twists = [], [], []
    for T in poses:
        for dev in (cam, rig.projector):
            uv = dev.project(apply_T(T, pts))
            assert np.all((uv >= 19.5) & (uv <= [dev.width - 20.5, dev.height - 20.5])), dev.name
            c = apply_T(T, centre[None])[0]
            to_dev = (dev.center - c) / np.linalg.norm(dev.center - c)
            assert -T[:3, 2] @ to_dev > np.cos(np.radians(60))  # printed side (-z) faces the device
        dist = np.linalg.norm(apply_T(T, centre[None])[0] - cam.center)
        assert 0.42 <= dist <= 0.58
        R_cam_board = cam.T_world_cam[:3, :3].T @ T[:3, :3]
        tilts.append(np.degrees(np.arccos(R_cam_board[2, 2])))
        twists.append(np.degrees(_twist_about_z(R_cam_board)))
        centres_uv.append(cam.project(apply_T(T, centre[None]))[0])
    tilts, twists, centres_uv = np.array(tilts), np.array(twists), np.array(centres_uv)
    assert tilts.min() >= 10 - 1e-9 and tilts.max() <= 45 + 1e-9 and np.ptp(tilts) > 20
    assert np.abs(twists).max() <= 30 + 1e-9 and np.ptp(twists) > 30
    assert np.ptp(centres_uv[:, 0]) > 300 and np.ptp(centres_uv[:, 1]) > 80  # spread over the image
    with pytest.raises(SceneError, match="outside image"):
        board_poses(rig, board, 3, distance=(0.2, 0.25), max_tries=200)


def test_builtin_board_lies_printed_side_up():
    placed = default_scene("board").objects[0]
    assert placed.texture is not None and placed.texture.image.shape == (1600, 2200)  # the default 10 x 7 board
    assert np.allclose(placed.world_vertices()[:, 2], 1e-3) and -placed.T_world_obj[2, 2] > 0.999


def test_turntable_board_stays_visible_and_moves_with_the_table(sim):
    rig = sim.rig
    board = Board()
    scene = turntable_board_scene(rig, board)
    obj = scene.objects[0]
    assert obj.on_turntable and "turntable" in scene.names
    x0, y0, x1, y1 = board.extent
    outline = np.array([[x, y, 0.0] for x in np.linspace(x0, x1, 12) for y in (y0, y1)]
                       + [[x, y, 0.0] for x in (x0, x1) for y in np.linspace(y0, y1, 12)])
    bottom = apply_T(obj.T_world_obj, np.array([[x0, y1, 0], [x1, y1, 0], [x0, y0, 0], [x1, y0, 0]]))
    assert np.allclose(bottom[:2, 2], 0) and np.all(bottom[2:, 2] > 0.1)  # standing on the table top
    assert np.all(np.linalg.norm(bottom[:, :2], axis=1) < 0.15)            # footprint on the disc
    centre = apply_T(obj.T_world_obj, np.array([[(x0 + x1) / 2, (y0 + y1) / 2, 0]]))[0]
    assert np.linalg.norm(centre[:2]) > 0.05                               # off the axis
    for deg in range(-40, 41, 10):
        T = compose(rig.T_world_rotated(np.radians(deg)), obj.T_world_obj)
        for dev in (rig.camera, rig.projector):
            uv = dev.project(apply_T(T, outline))
            assert np.all((uv >= 19.5) & (uv <= [dev.width - 20.5, dev.height - 20.5])), (deg, dev.name)
            assert -T[:3, 2] @ (dev.center - centre) > 0
    # rendered at +40 deg: the texture moves with the turntable
    sim.set_scene(scene)
    sim.turntable.rotate_to(np.radians(40))
    try:
        det = detect_board(sim.capture_sequence([WHITE])[0], board)
    finally:
        sim.turntable.rotate_to(0.0)
    T = compose(rig.T_world_rotated(np.radians(40)), obj.T_world_obj)
    assert det.found and np.linalg.norm(det.uv - rig.camera.project(apply_T(T, board.object_points())),
                                        axis=1).max() < 0.1
