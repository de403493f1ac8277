"""Active stereo (rangekit.stereo + rangekit.sim.sensors.stereo) against the simulator's exact truth.

Scene: the textureless white box, sphere and wall of :func:`stereo_scene` (0.6-1.1 m) seen by the
OAK-D-Pro-like pair of :func:`stereo_rig` at 320 x 200 (rectified focal 221.6 px, baseline 75 mm).
At 1.1 m one pixel of disparity is 73 mm of depth, at 0.7 m 30 mm.

"Matchable" pixels (the denominator of every coverage figure): ``visible`` (hit by the left camera and
seen unoccluded by the right one), true disparity inside the search range, and at least 5 px from the
image border (the census window and the rectification margin need the neighbourhood).
"""

import json

import numpy as np
import pytest

from rangekit.errors import InputError
from rangekit.geometry import apply_T
from rangekit.rig.rig_file import load_rig
from rangekit.sim.scene.raycast import cast_view
from rangekit.sim.sensors.stereo import render_stereo, speckle_pattern, stereo_rig, stereo_scene, write_stereo_capture
from rangekit.stereo import (census_transform, depth_in_camera, disparity_to_depth, disparity_to_points, rectify,
                             rectify_images, sgbm_disparity, sgm_disparity, stereo_depth)

W, H = 320, 200
MARGIN = 5


@pytest.fixture(scope="module")
def rig():
    return stereo_rig(W, H)


@pytest.fixture(scope="module")
def scene():
    return stereo_scene()


@pytest.fixture(scope="module")
def rect(rig):
    return rectify(*rig.cameras)


@pytest.fixture(scope="module")
def cap(rig, scene):
    return render_stereo(scene, rig, dots=True, seed=0)


@pytest.fixture(scope="module")
def cap_plain(rig, scene):
    return render_stereo(scene, rig, dots=False, seed=0)


@pytest.fixture(scope="module")
def n_disp(rect):
    return int(16 * np.ceil(rect.focal * rect.baseline / 0.4 / 16))  # what stereo_depth picks: 48


@pytest.fixture(scope="module")
def ours(cap, rig, n_disp):
    return stereo_depth(cap.left, cap.right, *rig.cameras, method="census-sgm")


@pytest.fixture(scope="module")
def peer(cap, rig, n_disp):
    return stereo_depth(cap.left, cap.right, *rig.cameras, method="sgbm")


def _matchable(cap, rect, n_disp) -> np.ndarray:
    d_true = rect.focal * rect.baseline / cap.depth  # rectified z differs from camera z by < 0.5% here
    m = cap.visible & (d_true < n_disp - 1)
    inner = np.zeros_like(m)
    inner[MARGIN:-MARGIN, MARGIN:-MARGIN] = True
    return m & inner


def _stats(depth, cap, mask):
    ok = mask & np.isfinite(depth)
    e = depth[ok] - cap.depth[ok]
    return {"coverage": ok.sum() / mask.sum(), "rms": float(np.sqrt(np.mean(e ** 2))),
            "median": float(np.median(np.abs(e))), "good_1cm": (np.abs(e) < 0.01).sum() / mask.sum()}


# ------------------------------------------------------------------------------------------ simulator
def test_capture_is_reproducible_and_truthful(cap, rig, scene):
    again = render_stereo(scene, rig, dots=True, seed=0)
    np.testing.assert_array_equal(cap.left, again.left)
    np.testing.assert_array_equal(cap.right, again.right)
    assert not np.array_equal(cap.left, render_stereo(scene, rig, seed=1).left)
    # every pixel sees the scene (the wall fills the view); depth and range agree with xyz
    assert cap.hit.all() and 0.6 < np.nanmin(cap.depth) and np.nanmax(cap.depth) < 1.11
    left = rig.cameras[0]
    p_cam = apply_T(left.T_cam_world, cap.xyz.reshape(-1, 3))
    np.testing.assert_allclose(p_cam[:, 2], cap.depth.ravel(), atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(p_cam, axis=1), cap.range.ravel(), atol=1e-12)
    # an occluded band exists beside the box and the sphere, and the dots reach nearly every visible pixel
    assert 0.03 < 1 - cap.visible.mean() < 0.2
    assert (cap.lit & cap.visible).sum() / cap.visible.sum() > 0.99


def test_dotless_images_are_flat_grey(cap_plain):
    for img in (cap_plain.left, cap_plain.right):
        assert 35 < img.mean() < 50 and img.std() < 3  # ambient only: 0.16 of full scale plus noise


def test_speckle_pattern():
    p = speckle_pattern(400, 300, density=0.2, dot_radius=1.5, seed=3)
    assert p.dtype == np.float32 and p.shape == (300, 400) and p.min() >= 0 and p.max() <= 1
    assert 0.12 < p.mean() < 0.2  # 20 % cover before overlaps
    np.testing.assert_array_equal(p, speckle_pattern(400, 300, density=0.2, dot_radius=1.5, seed=3))


def test_write_capture(tmp_path, cap, rig):
    paths = write_stereo_capture(cap, rig, tmp_path)
    assert [p.name for p in paths] == ["left.png", "right.png"]
    gt = np.load(tmp_path / "ground_truth.npz")
    assert set(gt.files) == {"depth", "range", "xyz", "hit", "valid", "T_world_cam"}
    np.testing.assert_array_equal(gt["valid"], cap.visible)
    info = json.loads((tmp_path / "capture.json").read_text())
    assert info["kind"] == "rangekit.sim.stereo/1" and info["dots"] is True and info["seed"] == 0
    back = load_rig(tmp_path / "rig.json")
    np.testing.assert_allclose(back.cameras[1].T_world_cam, rig.cameras[1].T_world_cam)
    assert (tmp_path / "preview.png").exists()


# ------------------------------------------------------------------------------------------ geometry
def test_rectification_aligns_rows(rig, rect, cap):
    """True points projected into both rectified images: same row, disparity f B / z (to 1e-6 px)."""
    left, right = rig.cameras
    X = cap.xyz[cap.hit]
    rl, rr = rect.cameras()
    ul = rl.project(X)
    # right image through the *original* right camera and R2, not through rect's own model
    Xr = apply_T(right.T_cam_world, X) @ rect.R2.T
    ur = Xr[:, :2] / Xr[:, 2:] * rect.focal + rect.P2[:2, 2]
    z_rect = apply_T(rl.T_cam_world, X)[:, 2]
    assert np.abs(ul[:, 1] - ur[:, 1]).max() < 1e-6
    np.testing.assert_allclose(ul[:, 0] - ur[:, 0], rect.focal * rect.baseline / z_rect, atol=1e-6)
    assert abs(rect.baseline - 0.075) < 1e-5
    # the remap table of the left image points at the raw pixel of each rectified pixel centre
    iu = np.clip(np.rint(ul).astype(int), 0, [W - 1, H - 1])
    raw = left.project(rl.rays(iu.astype(float))[1] + left.center)  # rays through the integer centres
    mx, my = rect.map_left
    np.testing.assert_allclose(np.column_stack([mx[iu[:, 1], iu[:, 0]], my[iu[:, 1], iu[:, 0]]]), raw, atol=2e-3)


def test_true_disparity_gives_true_depth(rig, rect, scene, cap):
    """disparity_to_depth / _points / depth_in_camera are exact when fed the exact disparity."""
    mesh = scene.world_mesh()
    rl, _ = rect.cameras()
    g = cast_view(mesh, rl, None)  # truth on the rectified grid
    d_true = rect.focal * rect.baseline / g.depth
    np.testing.assert_allclose(disparity_to_depth(d_true, rect), g.depth, rtol=1e-12)
    pts = disparity_to_points(d_true, rect, rig.cameras[0].T_world_cam)
    assert np.abs(pts - g.xyz.reshape(-1, 3)).max() < 1e-9
    # raw grid: bilinear disparity is exact on planes (1/z affine): test where the 5x5 neighbourhood is flat
    depth = depth_in_camera(d_true.astype(np.float32), rect, rig.cameras[0])
    left_truth = cast_view(mesh, rig.cameras[0], None)
    n = left_truth.normal
    flat = np.ones((H, W), bool)
    for dy in range(-2, 3):
        for dx in range(-2, 3):
            flat &= np.all(np.abs(np.roll(n, (dy, dx), axis=(0, 1)) - n) < 1e-9, axis=2)
    flat[:3], flat[-3:], flat[:, :3], flat[:, -3:] = False, False, False, False
    sel = flat & np.isfinite(depth)
    assert sel.sum() > 0.8 * H * W
    assert np.abs(depth[sel] - cap.depth[sel]).max() < 1e-6


# ------------------------------------------------------------------------------------------ matching
def test_census_transform_matches_reference():
    rng = np.random.default_rng(0)
    img = rng.integers(0, 8, (23, 31)).astype(np.float32)  # many ties: equal is not darker
    code = census_transform(img, (7, 5))
    pad = np.pad(img, ((2, 2), (3, 3)), mode="edge")
    ref = np.zeros(img.shape, np.uint64)
    for j in range(5):
        for i in range(7):
            if (i, j) == (3, 2):
                continue
            bit = (pad[j:j + 23, i:i + 31] < img).astype(np.uint64)
            ref = (ref << np.uint64(1)) | bit
    np.testing.assert_array_equal(code, ref)


def test_census_sgm_with_dots(ours, cap, rect, n_disp):
    """>= 95 % of the matchable pixels get a depth; median error 4-5 mm at 0.6-1.1 m (about 0.06 px)."""
    assert ours.disparity.num_disparities == n_disp == 48
    s = _stats(ours.depth, cap, _matchable(cap, rect, n_disp))
    print(f"census-SGM with dots: {s}")
    assert s["coverage"] >= 0.95
    assert s["median"] < 0.006
    assert s["good_1cm"] > 0.78
    assert s["rms"] < 0.025  # includes the few-pixel fringe at depth edges; a wrong matcher is > 0.1 m
    # world points are the depth pixels, on the true surface
    ok = np.isfinite(ours.depth)
    assert len(ours.points) == ok.sum()
    assert np.median(np.linalg.norm(ours.points - cap.xyz[ok], axis=1)) < 0.006
    assert ours.confidence[ok].mean() > 0.2 and np.all(ours.confidence[~ok] == 0)


def test_without_dots_matching_collapses(cap_plain, rig, rect, n_disp):
    """Same matcher, textureless scene, no projector: almost nothing is matched correctly."""
    res = stereo_depth(cap_plain.left, cap_plain.right, *rig.cameras)
    s = _stats(res.depth, cap_plain, _matchable(cap_plain, rect, n_disp))
    print(f"census-SGM without dots: {s}")
    assert s["good_1cm"] < 0.1
    assert s["coverage"] < 0.5 or s["rms"] > 0.1


def test_census_sgm_vs_opencv_sgbm(ours, peer, cap, rect, n_disp):
    m = _matchable(cap, rect, n_disp)
    a, b = _stats(ours.depth, cap, m), _stats(peer.depth, cap, m)
    print(f"census-SGM {a}\nOpenCV SGBM {b}")
    assert a["rms"] <= 1.5 * b["rms"]
    assert a["median"] <= 1.5 * b["median"]  # also without the few far-off outliers that dominate an RMS
    assert a["coverage"] >= b["coverage"] - 0.02


def test_left_right_check_removes_occlusions(ours, cap):
    occluded = cap.hit & ~cap.visible
    kept = occluded & np.isfinite(ours.depth)
    print(f"seen by the left camera only: {occluded.sum()} pixels, depth kept for {kept.sum() / occluded.sum():.1%}, "
          f"{(np.abs(ours.depth - cap.depth)[kept] > 0.05).mean():.0%} of those > 5 cm off")
    assert occluded.sum() > 500
    assert np.isnan(ours.depth[occluded]).mean() >= 0.8


def test_matchers_on_a_synthetic_shift():
    """A random texture shifted by a known sub-pixel amount (rectified input, no noise).

    Both matchers show "pixel locking" (the sub-pixel fit on an SGM-aggregated cost is biased towards
    integers): census-SGM by up to 0.11 px, OpenCV SGBM by up to 0.25 px at these shifts. Integer and
    half-pixel shifts are found to 0.02 px.
    """
    import cv2

    rng = np.random.default_rng(1)
    base = cv2.GaussianBlur(rng.uniform(0, 255, (80, 400)).astype(np.float32), (0, 0), 1.2)
    x = np.arange(300, dtype=np.float32)
    rows = np.tile(np.arange(80, dtype=np.float32)[:, None], (1, 300))
    right = cv2.remap(base, np.tile(x + 20, (80, 1)), rows, cv2.INTER_CUBIC)
    for shift, tol in ((7.0, 0.02), (7.25, 0.12), (7.5, 0.02), (7.75, 0.12)):
        left = cv2.remap(base, np.tile(x + 20 - shift, (80, 1)), rows, cv2.INTER_CUBIC)
        d = sgm_disparity(left, right, num_disparities=16).disparity[10:-10, 30:-10]
        assert np.isfinite(d).mean() > 0.95
        assert abs(np.nanmedian(d) - shift) < tol, (shift, np.nanmedian(d))
        d = sgbm_disparity(left, right, num_disparities=16).disparity[10:-10, 30:-10]
        assert abs(np.nanmedian(d) - shift) < 0.26, (shift, np.nanmedian(d))


# ------------------------------------------------------------------------------------------ bad input
def test_bad_input_messages(rig, cap, rect):
    left, right = rig.cameras
    with pytest.raises(InputError, match=r"left image is 320x200 but right is 160x100"):
        stereo_depth(cap.left, cap.right[::2, ::2], left, right)
    with pytest.raises(InputError, match=r"left image is 160x100 .* camera 'left' is 320x200"):
        stereo_depth(cap.left[::2, ::2], cap.right[::2, ::2], left, right)
    with pytest.raises(InputError, match=r"left image is 320x200 but right is 160x100"):
        sgm_disparity(cap.left, cap.right[::2, ::2])
    with pytest.raises(InputError, match=r"multiple of 16 .*found 40"):
        sgm_disparity(cap.left, cap.right, num_disparities=40)
    with pytest.raises(InputError, match=r"right image is 160x100 but the cameras are 320x200"):
        rectify_images(rect, cap.left, cap.right[::2, ::2])
    with pytest.raises(InputError, match=r"found shape \(200, 320, 4\)"):
        sgm_disparity(np.zeros((200, 320, 4)), np.zeros((200, 320, 4)))
    with pytest.raises(InputError, match=r"swap left and right"):
        rectify(right, left)


def test_rgb_input_is_converted(cap, rig):
    rgb_l = np.repeat(cap.left[:, :, None], 3, axis=2)
    rgb_r = np.repeat(cap.right[:, :, None], 3, axis=2)
    a = stereo_depth(rgb_l, rgb_r, *rig.cameras, num_disparities=48)
    b = stereo_depth(cap.left, cap.right, *rig.cameras, num_disparities=48)
    np.testing.assert_allclose(a.depth, b.depth, rtol=1e-5, equal_nan=True)


def test_cli_sim_render_then_stereo(tmp_path, capsys):
    """rangekit sim render --sensor stereo, then rangekit stereo on what it wrote; and its bad input."""
    import cv2

    from rangekit.cli import main

    pair, out = tmp_path / "pair", tmp_path / "out"
    assert main(["sim", "render", "--sensor", "stereo", "--size", "320x200", "--out", str(pair)]) == 0
    assert main(["stereo", str(pair / "left.png"), str(pair / "right.png"), "--rig", str(pair / "rig.json"),
                 "--out", str(out)]) == 0
    assert "against ground_truth.npz" in capsys.readouterr().out
    truth = np.load(pair / "ground_truth.npz")
    depth = np.load(out / "depth.npy")
    vis = truth["valid"]
    ok = vis & np.isfinite(depth)
    assert ok.sum() / vis.sum() > 0.9
    assert np.median(np.abs(depth - truth["depth"])[ok]) < 0.006
    from rangekit.formats.clouds import load_cloud
    assert len(load_cloud(out / "cloud.ply")) == int(np.isfinite(depth).sum())

    # A rig file with one camera, and a pair of two sizes: errors naming the file and both values.
    one = json.loads((pair / "rig.json").read_text())
    one["cameras"] = one["cameras"][:1]
    (tmp_path / "one.json").write_text(json.dumps(one))
    args = [str(pair / "left.png"), str(pair / "right.png")]
    assert main(["stereo", *args, "--rig", str(tmp_path / "one.json"), "--out", str(tmp_path / "o2")]) == 1
    assert "needs two cameras in 'cameras' (left = cameras[0], right = cameras[1]), found 1" in capsys.readouterr().err
    small = cv2.resize(cv2.imread(str(pair / "right.png"), cv2.IMREAD_UNCHANGED), (160, 100))
    cv2.imwrite(str(tmp_path / "small.png"), small)
    assert main(["stereo", args[0], str(tmp_path / "small.png"), "--rig", str(pair / "rig.json"),
                 "--out", str(tmp_path / "o3")]) == 1
    assert "left.png is 320x200 but" in capsys.readouterr().err


def test_every_visible_pixel_at_640x400():
    """The acceptance on all visible pixels, border included: at the sensor's own 640x400 with the
    rectification keeping more of the border (alpha 0.5), >= 95 % get a depth (measured 97.6 %)."""
    rig = stereo_rig(640, 400)
    cap = render_stereo(stereo_scene(), rig, seed=1)
    res = stereo_depth(cap.left, cap.right, *rig.cameras, alpha=0.5)
    ok = cap.visible & np.isfinite(res.depth)
    err = (res.depth - cap.depth)[ok]
    print(f"640x400 alpha 0.5: {ok.sum() / cap.visible.sum():.4f} of {cap.visible.sum()} visible, "
          f"RMS {np.sqrt(np.mean(err ** 2)) * 1e3:.2f} mm, median {np.median(np.abs(err)) * 1e3:.2f} mm")
    assert ok.sum() / cap.visible.sum() >= 0.95
    assert np.median(np.abs(err)) < 0.005 and np.sqrt(np.mean(err ** 2)) < 0.02


def test_alpha_half_at_320x200_trades_precision_for_border_pixels(ours, cap, rig):
    """Why alpha 0 stays the default: at 320x200 alpha 0.5 reaches more border pixels, but the rectified
    image is no longer enlarged, and the median error grows."""
    wide = stereo_depth(cap.left, cap.right, *rig.cameras, alpha=0.5)

    def figures(res):
        ok = cap.visible & np.isfinite(res.depth)
        return ok.sum() / cap.visible.sum(), float(np.median(np.abs(res.depth - cap.depth)[ok]))

    (c0, m0), (c5, m5) = figures(ours), figures(wide)
    print(f"320x200 all visible pixels: alpha 0 {c0:.1%} median {m0 * 1e3:.1f} mm; alpha 0.5 {c5:.1%} median "
          f"{m5 * 1e3:.1f} mm")
    assert c5 > c0 and m5 > 1.5 * m0
