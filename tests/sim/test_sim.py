"""The simulator against analytic answers: projector coordinates, shadows, image formation, noise."""

import cv2
import numpy as np
import pytest

from rangekit.errors import FileFormatError, PatternError, SceneError
from rangekit.geometry import apply_T, invert_T, look_at
from rangekit.coded.patterns import make_pattern_spec
from rangekit.sim import ImagingModel, Scene, SimRig, load_scene_object
from rangekit.sim.scene.objects import sphere


def _opencv_undistort(cam, uv):
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-16)
    return cv2.undistortPoints(uv.reshape(-1, 1, 2), cam.K, cam.dist, None, None, None, crit)[:, 0]


def test_plane_projector_map_equals_plane_induced_homography(rig, tilted_plane_scene):
    sim = SimRig(tilted_plane_scene, rig)
    truth = sim.ground_truth()
    assert truth.lit.mean() > 0.5
    cam, proj = rig.camera, rig.projector
    # Plane n.X = d in the camera frame, from the plane object's pose.
    T_cam_obj = invert_T(cam.T_world_cam) @ tilted_plane_scene.objects[0].T_world_obj
    n = T_cam_obj[:3, 2]
    d = n @ T_cam_obj[:3, 3]
    T_proj_cam = invert_T(proj.T_world_cam) @ cam.T_world_cam
    R, t = T_proj_cam[:3, :3], T_proj_cam[:3, 3]
    H = R + np.outer(t, n) / d  # x_proj ~ H x_cam in normalised coordinates (Fusiello / Hartley-Zisserman)
    v, u = np.nonzero(truth.lit)
    sel = np.random.default_rng(0).choice(u.size, 50000, replace=False)
    u, v = u[sel], v[sel]
    xc = _opencv_undistort(cam, np.column_stack([u, v]).astype(np.float64))
    xp = np.c_[xc, np.ones(len(xc))] @ H.T
    ref, _ = cv2.projectPoints(xp / xp[:, 2:], np.zeros(3), np.zeros(3), proj.K, proj.dist)
    err = np.hypot(truth.proj_col[v, u] - ref[:, 0, 0], truth.proj_row[v, u] - ref[:, 0, 1])
    print(f"\nplane: projector coordinates vs plane-induced homography: max {err.max():.2e} px, "
          f"RMS {np.sqrt(np.mean(err ** 2)):.2e} px over {err.size} lit pixels")
    assert err.max() <= 1e-3, f"max {err.max():.2e} px"
    # Depth and points agree with the same plane.
    X = truth.xyz[v, u]
    assert np.abs(apply_T(invert_T(cam.T_world_cam), X) @ n - d).max() < 1e-12


def _segment_hits_box(p, q, lo, hi):
    """Slab test: does the open segment p->q (each (N, 3)) cross the axis-aligned box [lo, hi]?"""
    dvec = q - p
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (lo - p) / dvec
        t2 = (hi - p) / dvec
    tmin = np.nanmax(np.minimum(t1, t2), axis=1)
    tmax = np.nanmin(np.maximum(t1, t2), axis=1)
    return (tmax >= np.maximum(tmin, 1e-9)) & (tmin < 1 - 1e-9)


def test_box_on_plane_casts_the_geometric_shadow(rig, box_on_plane_scene):
    sim = SimRig(box_on_plane_scene, rig)
    truth = sim.ground_truth()
    cam, proj = rig.camera, rig.projector
    cube = box_on_plane_scene.objects[1]
    corners = cube.world_vertices()
    lo, hi = corners.min(axis=0), corners.max(axis=0)
    # Analytic: camera ray meets z = 0 unless the box is in front; that plane point is lit unless
    # the segment to the projector centre crosses the box (or it is outside the projector image).
    o, dirs = cam.rays(cam.pixel_grid())
    t = -o[:, 2] / dirs[:, 2]
    X = o + t[:, None] * dirs
    on_plane = (t > 0) & np.all(np.abs(X[:, :2]) <= 0.5, axis=1) & ~_segment_hits_box(o, X, lo, hi)
    uvp = proj.project(X)
    in_image = (uvp[:, 0] >= -0.5) & (uvp[:, 0] < proj.width - 0.5) & (uvp[:, 1] >= -0.5) & \
               (uvp[:, 1] < proj.height - 0.5)
    shadow = _segment_hits_box(X, np.broadcast_to(proj.center, X.shape), lo, hi)
    lit_analytic = on_plane & in_image & ~shadow
    sim_on_plane = (truth.object_id.ravel() == 0)
    lit_sim = truth.lit.ravel() & sim_on_plane
    assert np.mean(on_plane == sim_on_plane) >= 0.999
    agree = np.mean(lit_analytic == lit_sim)
    n_shadow = np.count_nonzero(on_plane & in_image & shadow)
    assert n_shadow > 5000, "the test scene must cast a real shadow"
    print(f"\nbox on plane: lit/shadow mask agreement {agree:.6f} over {lit_sim.size} "
          f"pixels ({np.count_nonzero(lit_analytic != lit_sim)} differ; {n_shadow} shadowed plane pixels)")
    assert agree >= 0.999, f"shadow mask agreement {agree:.5f}"
    # Shadowed plane points get no projector light in a white capture (noise-free).
    sim_nf = SimRig(box_on_plane_scene, rig, imaging=ImagingModel(camera_blur=0.0).noiseless())
    white = sim_nf.renderer().expected(np.full((800, 1280), 255, np.uint8)).ravel()
    dark = on_plane & in_image & shadow & sim_on_plane
    assert np.abs(white[dark] - 0.6 * 0.01).max() < 1e-6  # ambient light only
    lit_both = lit_analytic & lit_sim
    assert white[lit_both].min() > 3 * 0.6 * 0.01  # lit points get projector light on top of ambient


def test_image_formation_matches_the_model(rig, tilted_plane_scene):
    model = ImagingModel(camera_blur=0.0, projector_blur=0.0, gamma=2.2, black_level=0.0, ambient=0.05,
                         global_fraction=0.3).noiseless()
    sim = SimRig(tilted_plane_scene, rig, imaging=model)
    truth = sim.ground_truth()
    grey = np.full((800, 1280), 128, np.uint8)
    E = sim.renderer().expected(grey)
    L = (128 / 255) ** 2.2
    albedo = truth.albedo.mean(axis=2)
    ref = albedo * (0.05 + 0.3 * L)
    ref = ref + np.where(truth.lit, L * albedo * truth.cos_proj * (0.5 / truth.proj_dist) ** 2, 0.0)
    assert np.abs(E - ref).max() < 1e-6
    # The Lambertian factor itself: cos between the true normal and the direction to the projector.
    v, u = np.nonzero(truth.lit)
    to_p = rig.projector.center - truth.xyz[v, u]
    cos = np.sum(truth.normal[v, u] * to_p, axis=1) / np.linalg.norm(to_p, axis=1)
    assert np.abs(cos - truth.cos_proj[v, u]).max() < 1e-12


@pytest.mark.slow
def test_noise_mean_and_variance_follow_the_model(rig, tilted_plane_scene):
    model = ImagingModel(bits=16, full_well=5000.0, read_noise=20.0)
    sim = SimRig(tilted_plane_scene, rig, imaging=model, seed=3)
    ren = sim.renderer()
    white = np.tile(np.linspace(60, 255, 1280).astype(np.uint8), (800, 1))  # many signal levels
    expected = ren.expected(white)
    rows = slice(200, 800)
    frames = np.stack([ren.render(white, np.random.default_rng(i))[rows].astype(np.float64) / model.max_value
                       for i in range(60)])
    exp = expected[rows].astype(np.float64)
    use = (exp > 0.02) & (exp < 0.8)
    assert use.sum() > 100000
    mean = frames.mean(axis=0)[use]
    var = frames.var(axis=0, ddof=1)[use]
    e = exp[use]
    model_var = model.noise_std(e) ** 2 + 1 / (12 * model.max_value ** 2)
    # Mean within 5% of its own noise band is too strict pixel-wise; compare pooled, in signal bins.
    assert abs(np.mean(mean - e)) < 0.05 * np.mean(np.sqrt(model_var))
    for lo, hi in ((0.02, 0.1), (0.1, 0.25), (0.25, 0.8)):
        b = (e >= lo) & (e < hi)
        assert b.sum() > 5000
        ratio = var[b].mean() / model_var[b].mean()
        print(f"\nnoise, signal in [{lo}, {hi}): variance measured/model {ratio:.4f}, "
              f"mean measured/model {mean[b].mean() / e[b].mean():.5f}")
        assert abs(ratio - 1) < 0.05, f"variance ratio {ratio:.3f} in [{lo}, {hi})"
        assert abs(mean[b].mean() / e[b].mean() - 1) < 0.05


def test_turntable_rotates_the_objects(rig):
    ball = sphere(0.04, subdivisions=5).placed_on_table(xy=(0.05, 0.0))
    sim = SimRig(Scene((ball,)), rig)
    centre0 = apply_T(ball.T_world_obj, np.zeros((1, 3)))[0]
    for angle in (0.0, np.radians(90.0)):
        sim.turntable.rotate_to(angle)
        truth = sim.ground_truth()
        c = np.array([np.cos(angle) * centre0[0], np.sin(angle) * centre0[0], centre0[2]])
        r = np.linalg.norm(truth.xyz[truth.hit] - c, axis=1)
        # Chordal error of a level-5 icosphere of radius 4 cm is below 0.02 mm.
        assert 0.04 - 2e-5 < r.min() and r.max() <= 0.04 + 1e-12


@pytest.mark.slow
def test_noise_is_reproducible_per_capture_state(rig, tilted_plane_scene):
    spec = make_pattern_spec("graycode", (1280, 800))
    frames = [spec.frame(i) for i in (0, 5, 9)]
    a = SimRig(tilted_plane_scene, rig, seed=7)
    b = SimRig(tilted_plane_scene, rig, seed=7)
    seq = a.capture_sequence(frames)
    one_by_one = []
    for f in frames:
        b.projector.show(f)
        one_by_one.append(b.camera.capture())
    assert all(np.array_equal(x, y) for x, y in zip(seq, one_by_one))
    again = b.capture_sequence(frames[:1])[0]  # second capture of the same state: new noise
    assert not np.array_equal(again, seq[0])
    other_seed = SimRig(tilted_plane_scene, rig, seed=8).capture_sequence(frames[:1])[0]
    assert not np.array_equal(other_seed, seq[0])


def test_sim_devices_implement_the_protocols(rig, tilted_plane_scene):
    from rangekit.rig import devices

    sim = SimRig(tilted_plane_scene, rig)
    assert isinstance(sim.camera, devices.Camera)
    assert isinstance(sim.projector, devices.Projector)
    assert isinstance(sim.turntable, devices.Turntable)
    assert isinstance(sim, devices.RigDevices)


def test_bad_input_gives_clear_errors(rig, tmp_path, tilted_plane_scene):
    garbage = tmp_path / "broken.ply"
    garbage.write_bytes(b"\x00\x01not a mesh at all\xff" * 10)
    with pytest.raises((FileFormatError, SceneError), match="broken.ply"):
        load_scene_object(garbage)
    empty = tmp_path / "empty.obj"
    empty.write_text("# no vertices\n")
    with pytest.raises((FileFormatError, SceneError), match="empty.obj"):
        load_scene_object(empty)
    away = rig.camera.with_pose(look_at([0, -0.5, 0.2], [0, -1.5, 0.2]))
    from rangekit.rig.rig_file import Rig

    blind = Rig(cameras=(away,), projector=rig.projector, T_world_table=rig.T_world_table)
    with pytest.raises(SceneError, match="sees nothing"):
        SimRig(tilted_plane_scene, blind).ground_truth()
    sim = SimRig(tilted_plane_scene, rig)
    with pytest.raises(PatternError, match=r"1280x800.*\(800, 1280\).*found \(600, 800\)"):
        sim.projector.show(np.zeros((600, 800), np.uint8))
    with pytest.raises(PatternError, match=r"\(800, 1280\)"):
        sim.renderer().expected(np.zeros((800, 1000), np.uint8))


def test_specular_highlight_follows_blinn_phong(rig):
    from dataclasses import replace

    ball = replace(sphere(0.05, subdivisions=5, specular=0.6, shininess=30.0).placed_on_table(), name="shiny")
    model = ImagingModel(camera_blur=0.0, projector_blur=0.0, ambient=0.0).noiseless()
    sim = SimRig(Scene((ball,)), rig, imaging=model)
    truth = sim.ground_truth()
    E = sim.renderer().expected(np.full((800, 1280), 255, np.uint8))
    v, u = np.nonzero(truth.lit)
    X, n = truth.xyz[v, u], truth.normal[v, u]
    l = rig.projector.center - X
    d_p = np.linalg.norm(l, axis=1)
    l /= d_p[:, None]
    view = rig.camera.center - X
    view /= np.linalg.norm(view, axis=1, keepdims=True)
    h = (l + view) / np.linalg.norm(l + view, axis=1, keepdims=True)
    L = 1.0  # white, black level does not matter at full white: 0.001 + 0.999 * 1
    ref = L * (0.8 * np.sum(n * l, axis=1) + 0.6 * np.clip(np.sum(n * h, axis=1), 0, 1) ** 30) * (0.5 / d_p) ** 2
    assert np.abs(E[v, u] - ref).max() < 1e-5
    assert (E[v, u] - 0.8 * np.sum(n * l, axis=1) * (0.5 / d_p) ** 2).max() > 0.3  # a real highlight


def test_projector_defocus_blurs_a_stripe_edge(rig, tilted_plane_scene):
    from scipy.ndimage import gaussian_filter1d

    sigma = 1.5
    model = ImagingModel(camera_blur=0.0, projector_blur=sigma, gamma=1.0, black_level=0.0, ambient=0.0).noiseless()
    sim = SimRig(tilted_plane_scene, rig, imaging=model)
    truth = sim.ground_truth()
    ren = sim.renderer()
    step = np.zeros((800, 1280), np.uint8)
    step[:, :640] = 255
    ratio = ren.expected(step) / np.where(truth.lit, ren.expected(np.full_like(step, 255)), np.nan)
    row_profile = gaussian_filter1d(np.r_[np.ones(640), np.zeros(640)], sigma, mode="nearest", truncate=6)
    near = truth.lit & (np.abs(truth.proj_col - 639.5) < 6) & (truth.proj_row > 50) & (truth.proj_row < 750)
    ref = np.interp(truth.proj_col[near], np.arange(1280), row_profile)
    assert near.sum() > 1000
    assert np.abs(ratio[near] - ref).max() < 2e-3
