"""rangekit.sim.sensors.lightstage: images agree with the truth they come with (camera frame, shadows, falloff)."""

import numpy as np
import pytest

from rangekit.errors import InputError
from rangekit.sim.sensors.lightstage import (LIGHT_STAGE_MODEL, light_stage_camera, light_stage_lights, light_stage_scene,
                                     render_light_stage)
from rangekit.sim.imaging.render import ImagingModel

EXACT = ImagingModel(bits=16, ambient=0.0, camera_blur=0.0, full_well=0.0, read_noise=0.0)
LSB = 1.0 / 65535
SIDE = np.array([0.97, 0.0, -0.24]) / np.linalg.norm([0.97, 0.0, -0.24])  # from the right, camera side


@pytest.fixture(scope="module")
def camera():
    return light_stage_camera(160, 128)


def _points(cap) -> np.ndarray:
    """(H, W, 3) camera-frame surface points from the true depth and the pixel rays."""
    cam = cap.camera
    d = cam.rays(cam.pixel_grid())[1].reshape(cam.height, cam.width, 3)  # world = camera frame here
    return d * (cap.depth_true / d[..., 2])[..., None]


def test_lights_face_the_camera():
    L = light_stage_lights(96, rng=3)
    np.testing.assert_allclose(np.linalg.norm(L, axis=1), 1.0)
    angle = np.degrees(np.arccos(-L[:, 2]))
    assert angle.min() >= 5 - 1e-9 and angle.max() <= 45 + 1e-9
    np.testing.assert_array_equal(L, light_stage_lights(96, rng=3))


def test_truth_matches_images_lambertian(camera):
    """Noiseless, no specular, no cast shadows: I = albedo * n.l to 16-bit precision; truth in camera frame."""
    scene = light_stage_scene("sphere", specular=0.5, shininess=30.0)
    L = light_stage_lights(12, rng=1)
    cap = render_light_stage(scene, L, camera=camera, model=EXACT, specular=False, shadows=False)
    m = cap.mask
    assert cap.images.shape == (12, 128, 160) and cap.images.dtype == np.float32
    n = cap.normals_true
    assert np.all(np.isnan(n[~m])) and np.all(n[m][:, 2] < 0.05)
    # The sphere's normals are (x - c) / r in the camera frame (c = (0, 0, 0.5), r = 0.05).
    x = _points(cap)
    true_n = (x[m] - [0.0, 0.0, 0.5]) / 0.05
    np.testing.assert_allclose(np.linalg.norm(true_n, axis=1), 1.0, atol=5e-4)  # facets lie <= 1e-5 m inside the sphere
    ang = np.degrees(np.arccos(np.clip(np.sum(true_n / np.linalg.norm(true_n, axis=1, keepdims=True) * n[m],
                                              axis=1), -1, 1)))
    assert ang.max() < 0.5, ang.max()
    assert np.nanmin(cap.depth_true) == pytest.approx(0.45, abs=2e-4)
    np.testing.assert_allclose(cap.albedo_true[m], 0.8)
    shading = np.einsum("fhwk,hwk->fhw", np.broadcast_to(L[:, None, None, :], (12,) + n.shape), np.nan_to_num(n))
    expect = 0.8 * np.clip(shading, 0, None)
    assert np.abs(cap.images[:, m] - expect[:, m]).max() <= 0.5 * LSB + 1e-7
    np.testing.assert_array_equal(cap.shadowed[:, m], shading[:, m] <= 0)
    assert not cap.cast_shadow.any() and np.all(cap.images[:, ~m] == 0)
    # With specular on, the highlight adds light (never removes it) where the surface is lit.
    spec = render_light_stage(scene, L, camera=camera, model=EXACT, shadows=False)
    extra = spec.images[:, m] - cap.images[:, m]
    assert extra.min() >= -LSB and extra.max() > 0.3


def test_least_squares_recovers_normals_from_noisy_images(camera):
    """The default sensor (16-bit, shot + read noise, lens blur) keeps Lambertian PS accurate inside."""
    scene = light_stage_scene("sphere")
    L = light_stage_lights(24, rng=2)
    cap = render_light_stage(scene, L, camera=camera, model=LIGHT_STAGE_MODEL, rng=5)
    inner = cap.mask & ~cap.shadowed.any(axis=0)
    inner &= np.roll(inner, 2, 0) & np.roll(inner, -2, 0) & np.roll(inner, 2, 1) & np.roll(inner, -2, 1)
    X = np.linalg.lstsq(L, cap.images[:, inner].astype(np.float64), rcond=None)[0].T
    n = X / np.linalg.norm(X, axis=1, keepdims=True)
    ang = np.degrees(np.arccos(np.clip(np.sum(n * cap.normals_true[inner], axis=1), -1, 1)))
    assert inner.sum() > 500 and ang.mean() < 0.5, (inner.sum(), ang.mean())
    np.testing.assert_allclose(np.linalg.norm(X, axis=1), cap.albedo_true[inner], rtol=0.02)


def test_box_casts_a_shadow_on_the_sphere(camera):
    L = SIDE[None]
    free = render_light_stage(light_stage_scene("sphere"), L, camera=camera, rng=0)
    boxed = render_light_stage(light_stage_scene("sphere", occluder=True), L, camera=camera, rng=0)
    sphere = free.mask & (free.depth_true < 0.55) & (np.abs(_points(free)[..., 0]) < 0.05)
    facing = sphere & ~free.shadowed[0]
    cast = boxed.cast_shadow[0] & sphere
    assert not free.cast_shadow.any()
    assert cast.sum() > 0.95 * facing.sum()  # the box hides the whole lit side from this light
    assert free.images[0][cast].mean() > 0.2 and boxed.images[0][cast].max() < 0.01
    assert np.all(boxed.shadowed[0][cast])
    # Light from the left: the box (on the right) casts nothing on the sphere.
    left = render_light_stage(light_stage_scene("sphere", occluder=True), SIDE[None] * [-1, 1, 1], camera=camera)
    assert not (left.cast_shadow[0] & sphere).any()


def test_lumpy_object_shadows_itself(camera):
    cap = render_light_stage(light_stage_scene("lumpy"), np.array([[0.0, -0.94, -0.34]]) / np.hypot(0.94, 0.34), camera=camera,
                             model=EXACT, specular=False)
    cast = cap.cast_shadow[0]
    assert 20 < cast.sum() < 0.5 * cap.mask.sum()
    assert np.all(cap.images[0][cast] == 0)


def test_point_light_falloff(camera):
    """Point lights: per-pixel direction and (ref_distance / d)^2, ref_distance = 0.5 m."""
    scene = light_stage_scene("sphere", albedo=0.3)
    P = np.array([[0.0, 0.0, 0.15], [0.0, 0.0, 0.0], [0.1, -0.1, 0.3], [0.0, 0.0, 0.4]])  # metres, camera frame
    cap = render_light_stage(scene, P, camera=camera, kind="point", model=EXACT, specular=False)
    m = cap.mask
    x = _points(cap)[m]
    to = P[:, None, :] - x[None]
    d = np.linalg.norm(to, axis=2)
    cos = np.einsum("fnk,nk->fn", to / d[..., None], cap.normals_true[m])
    expect = 0.3 * np.clip(cos, 0, None) * (0.5 / d) ** 2
    assert np.abs(cap.images[:, m] - np.minimum(expect, 1.0)).max() <= 0.5 * LSB + 2e-6
    # Front of the sphere (z = 0.45): 0.3 m from light 0, 0.45 m from light 1 -> ratio (0.45 / 0.3)^2.
    front = np.unravel_index(np.nanargmin(cap.depth_true), m.shape)
    ratio = cap.images[0][front] / cap.images[1][front]
    assert ratio == pytest.approx((0.45 / 0.3) ** 2, rel=2e-3)
    assert cap.images[3][front] == 1.0  # 0.05 m away: 0.3 * 100 clips at full scale


def test_reproducible_with_seed(camera):
    scene = light_stage_scene("sphere", specular=0.3)
    L = light_stage_lights(4, rng=0)
    a = render_light_stage(scene, L, camera=camera, rng=7)
    b = render_light_stage(scene, L, camera=camera, rng=7)
    c = render_light_stage(scene, L, camera=camera, rng=8)
    np.testing.assert_array_equal(a.images, b.images)
    assert np.any(a.images != c.images)
    diff = (a.images - c.images)[:, a.mask & ~a.shadowed.any(0)]
    # Two independent noise draws: std of their difference is sqrt(2) x the model's noise.
    signal = a.images[:, a.mask & ~a.shadowed.any(0)]
    expected = np.sqrt(2) * LIGHT_STAGE_MODEL.noise_std(signal).mean()
    assert diff.std() == pytest.approx(expected, rel=0.1)


def test_bad_input(camera):
    scene = light_stage_scene("sphere")
    with pytest.raises(InputError, match="unit vectors"):
        render_light_stage(scene, np.array([[0.0, 0.0, -2.0]]), camera=camera)
    with pytest.raises(InputError, match=r"\(f, 3\)"):
        render_light_stage(scene, np.zeros((2, 2)), camera=camera)
    with pytest.raises(InputError, match="kind"):
        render_light_stage(scene, SIDE[None], camera=camera, kind="area")
    with pytest.raises(InputError, match="intensities"):
        render_light_stage(scene, SIDE[None], camera=camera, intensities=[1.0, 2.0])
    with pytest.raises(InputError, match="max_angle"):
        light_stage_lights(4, max_angle=2.0)
