"""Photometric stereo on the zoo's hard objects: the light stage's interreflection
against the analytic spherical cavity, and the robust method against least squares on ``bowl`` and
``shiny`` (cast shadows, one bounce of interreflection, saturated highlights), small images."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from rangekit.errors import InputError
from rangekit.photometric import angular_error, photometric_stereo
from rangekit.photometric.cavity_light import MIN_LIGHTS, cavity_light
from rangekit.photometric.solve import solve_chunks, to_maps
from rangekit.sim.sensors.lightstage import (LIGHT_STAGE_MODEL, light_stage_camera, light_stage_lights, light_stage_scene,
                                     render_light_stage)

CLEAN = replace(LIGHT_STAGE_MODEL, full_well=0.0, read_noise=0.0, camera_blur=0.0)


def test_no_bounce_on_a_convex_object():
    """Every bounce ray from a lone sphere escapes: the images are those of the direct light, bit for bit."""
    cam = light_stage_camera(96, 76)
    lights = light_stage_lights(4, rng=0)
    with_bounce = render_light_stage(light_stage_scene("sphere"), lights, camera=cam, bounce_samples=8)
    without = render_light_stage(light_stage_scene("sphere"), lights, camera=cam, bounce_samples=0)
    np.testing.assert_array_equal(with_bounce.images, without.images)


def test_bowl_interreflection_matches_the_spherical_cavity():
    """Inside a sphere of radius r every wall patch dA' lights a point by ``L dA' / (4 r^2)``; the light
    entering the opening (pi r^2 cos(theta)) all lands on the inner hemisphere, so one bounce adds
    ``albedo(x) * albedo * cos(theta) / 4`` everywhere inside, whatever the shadows."""
    cam = light_stage_camera(128, 102)
    lights = light_stage_lights(6, rng=3)
    scene = light_stage_scene("bowl")                  # albedo 0.8, inner radius 50 mm, facing the camera
    a = render_light_stage(scene, lights, camera=cam, model=CLEAN, bounce_samples=16)
    b = render_light_stage(scene, lights, camera=cam, model=CLEAN, bounce_samples=0)
    rim_depth = np.nanmin(a.depth_true)
    inside = a.mask & (a.depth_true > rim_depth + 2e-3)
    assert inside.sum() > 0.5 * a.mask.sum()           # the camera looks into the bowl
    bounce = (a.images - b.images)[:, inside] / a.albedo_true[inside][None]  # (f, pixels)
    expected = 0.8 * -lights[:, 2] / 4                 # cos(theta) to the bowl's axis, the camera's -z
    np.testing.assert_allclose(np.median(bounce, axis=1), expected, rtol=0.04)  # measured within 2%
    rim = a.mask & (np.abs(a.depth_true - rim_depth) < 1e-6)
    assert np.abs(a.images - b.images)[:, rim].max() < 1e-4  # the flat rim faces away from the walls


@pytest.fixture(scope="module")
def zoo_captures():
    cam = light_stage_camera(160, 128)
    lights = light_stage_lights(48, rng=0)
    return {obj: render_light_stage(light_stage_scene(obj), lights, camera=cam, bounce_samples=16)
            for obj in ("bowl", "shiny")}


@pytest.mark.parametrize("obj, ls_min", [("bowl", 6.0), ("shiny", 10.0)])
def test_robust_beats_least_squares_on_hard_objects(zoo_captures, obj, ls_min):
    """Issue 18 acceptance: robust <= 0.6 x least squares (measured 0.35 on the bowl, 0.29 on shiny)."""
    cap = zoo_captures[obj]
    if obj == "shiny":
        assert (cap.images[:, cap.mask] >= 1.0).mean() > 0.03   # highlights saturate (5.7%)
    else:
        assert cap.cast_shadow[:, cap.mask].mean() > 0.1        # the rim shadows the walls (18%)
    ls = angular_error(photometric_stereo(cap.images, cap.lights, cap.mask, method="ls").normals,
                       cap.normals_true, cap.mask).mean_deg
    rob = angular_error(photometric_stereo(cap.images, cap.lights, cap.mask, method="robust").normals,
                        cap.normals_true, cap.mask).mean_deg
    assert ls > ls_min, ls                                       # measured 8.90 (bowl), 13.18 (shiny)
    assert rob <= 0.6 * ls, (rob, ls)                            # measured 3.11, 3.85


def test_bowl_needs_the_interreflection_correction(zoo_captures):
    """Without removing the reflected light the trimmed IRLS fit alone stays at 0.64 x least squares."""
    cap = zoo_captures["bowl"]
    B = cap.images[:, cap.mask].T

    def err(rounds: int) -> float:
        n, _ = to_maps(solve_chunks(B, cap.lights.T, "robust", global_rounds=rounds)[0], cap.mask)
        return angular_error(n, cap.normals_true, cap.mask).mean_deg

    assert err(0) > 4.5 and err(3) < 0.6 * err(0), (err(0), err(3))  # measured 5.67 and 2.67


def test_cavity_light_recovers_a_linear_term_exactly():
    rng = np.random.default_rng(5)
    S = light_stage_lights(12, rng=1).T                           # (3, f)
    k = np.array([0.01, -0.02, -0.2])
    rho = rng.uniform(0.2, 0.9, 400)
    shadow = rng.random((400, 12)) < 0.3
    B = np.where(shadow, rho[:, None] * (k @ S)[None], 1.0)
    found = cavity_light(B, rho, shadow, S)
    assert found.applied and found.spread < 1e-9 and found.misfit < 1e-9 and found.coverage > 0.9
    np.testing.assert_allclose(found.beta, k @ S, rtol=1e-12)
    assert "removed" in found.describe()
    few = shadow & (np.arange(12) < MIN_LIGHTS - 1)[None]          # 5 lights with shadows: nothing to fit
    nothing = cavity_light(B, rho, few, S)
    assert not nothing.applied and nothing.lights == MIN_LIGHTS - 1
    np.testing.assert_array_equal(nothing.beta, 0.0)


def test_light_that_varies_from_pixel_to_pixel_is_not_a_cavity():
    """The same shadows and mean light as above, but each shadowed pixel receives its own amount (a fold
    lit by its nearest wall): the spread refuses it and nothing is subtracted."""
    rng = np.random.default_rng(5)
    S = light_stage_lights(12, rng=1).T
    k = np.array([0.01, -0.02, -0.2])
    rho = rng.uniform(0.2, 0.9, 400)
    shadow = rng.random((400, 12)) < 0.3
    B = np.where(shadow, rho[:, None] * (k @ S)[None] * rng.uniform(0.0, 2.0, (400, 1)), 1.0)
    found = cavity_light(B, rho, shadow, S)
    assert not found.applied and found.spread > 0.5 and "does not hold" in found.describe()
    np.testing.assert_array_equal(found.beta, 0.0)


@pytest.mark.parametrize("obj", ["bunny", "steps", "thin"])
def test_real_like_concave_objects_are_not_touched(obj):
    """Cast shadows lit by nearby walls (bunny's ears, the foot of the steps, the thin object's folds), as on
    real objects: the correction must leave them alone (it made them 0.5, 6.2 and 2.1 deg worse)."""
    cap = render_light_stage(light_stage_scene(obj), light_stage_lights(48, rng=0), camera=light_stage_camera(160, 128),
                             bounce_samples=16)
    res = photometric_stereo(cap.images, cap.lights, cap.mask, method="robust")
    assert "not applied" in res.interreflection, res.interreflection
    B = cap.images[:, cap.mask].T
    untouched, _ = to_maps(solve_chunks(B, cap.lights.T, "robust", global_rounds=0)[0], cap.mask)
    np.testing.assert_array_equal(res.normals, untouched)


def test_the_bowl_says_its_interreflection_was_removed(zoo_captures):
    cap = zoo_captures["bowl"]
    res = photometric_stereo(cap.images, cap.lights, cap.mask, method="robust")
    assert res.interreflection.startswith("interreflection of a concave object removed"), res.interreflection
    ls = photometric_stereo(cap.images, cap.lights, cap.mask, method="ls")
    assert ls.interreflection == ""


def test_bounce_samples_checked():
    with pytest.raises(InputError, match="bounce_samples"):
        render_light_stage(light_stage_scene("sphere"), light_stage_lights(3, rng=0),
                           camera=light_stage_camera(32, 26), bounce_samples=-1)
