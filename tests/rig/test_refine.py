"""The rig refined from a capture's own correspondences (rangekit.rig.refine, issue 47), against exact truth.

Synthetic correspondences: 20000 points on a bumpy sphere (radius 8 cm, 8 % bumps) at the default rig's target, seen
by both devices, projected exactly (lens distortion included) with 0.2 px Gaussian noise in each device. The second
device is then turned 0.4 deg about a tilted world axis and its centre moved 5 mm on the sphere about the camera (the
baseline length kept): the rig check is 6.8 px off for the projector, 6.5 px for a second camera.

Tolerances, about 4x the RMS error measured over 12 noise seeds (RMS, largest):
- pose only: 0.04 deg (projector 0.009, 0.016; second camera 0.011, 0.019; 10 % wrong decodes 0.010, 0.024) and
  0.15 mm (0.033, 0.059; 0.029, 0.045; 0.037, 0.077);
- focal length freed too (given 15 px, 1 %, too long): 0.05 deg (0.013, 0.021), 0.75 mm (0.18, 0.34), f 3 px
  (0.69, 1.35);
- the check after the refinement is at the noise, 0.17-0.19 px: under 0.3 px.
From a simulated decode (the small rig, Gray code with rows): the projector turned 0.5 deg comes back to 0.014 deg and
0.14 mm of the truth from every start (the decoding's own bias along what two views fix worst): tolerance 0.05 deg and
0.5 mm; the check after it 0.01 px (tolerance 0.1).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import rangekit.rig.refine as refine_module
from rangekit.errors import CalibrationError, InputError
from rangekit.geometry import axis_angle_to_R, look_at, make_T, rotation_angle
from rangekit.rig.capture_check import check_rig
from rangekit.rig.refine import MIN_POINTS, refine_extrinsics
from rangekit.sim import default_rig

TARGET = np.array([0.0, 0.0, 0.06])            # the default rig's devices aim here (world frame, metres)


def _bumpy_sphere(first, second, n=20_000, seed=0):
    """(n, 3) world points on a bumpy sphere about TARGET, on the side both devices face."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(6 * n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    P = TARGET + (0.08 * (1 + 0.08 * np.sin(5 * d[:, 0]) * np.cos(4 * d[:, 1])))[:, None] * d
    seen = (np.sum(d * (first.center - P), axis=1) > 0) & (np.sum(d * (second.center - P), axis=1) > 0)
    return P[seen][:n]


def _plane(n=20_000, seed=0):
    """(n, 3) world points on a 20 cm square through TARGET, facing the rig."""
    rig = default_rig()
    normal = 0.5 * (rig.camera.center + rig.projector.center) - TARGET
    axes = np.linalg.svd((normal / np.linalg.norm(normal))[None, :])[2][1:]
    return TARGET + np.random.default_rng(seed).uniform(-0.1, 0.1, (n, 2)) @ axes


def _pixels(P, first, second, noise_px=0.2, seed=1):
    rng = np.random.default_rng(seed)
    uv1, uv2 = first.project(P), second.project(P)
    return uv1 + rng.normal(0, noise_px, uv1.shape), uv2 + rng.normal(0, noise_px, uv2.shape)


def _moved(device, origin, degrees=0.4, axis=(1.0, 2.0, 0.5), mm=5.0):
    """``device`` turned by ``degrees`` about a world ``axis`` through its centre, its centre moved by ``mm`` on the
    sphere about ``origin`` (the baseline length kept)."""
    offset = device.center - origin
    side = np.cross(offset, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side)
    up = np.cross(offset, side)
    up /= np.linalg.norm(up)
    new = offset + mm * 1e-3 * (0.6 * up + 0.8 * side)
    R = axis_angle_to_R(np.array(axis), np.radians(degrees)) @ device.T_world_cam[:3, :3]
    return device.with_pose(make_T(R, origin + new * np.linalg.norm(offset) / np.linalg.norm(new)))


def _errors(refined, truth):
    """(degrees, millimetres) between a refined device's pose and the truth."""
    turn = refined.T_world_cam[:3, :3] @ truth.T_world_cam[:3, :3].T
    return np.degrees(rotation_angle(turn)), 1e3 * np.linalg.norm(refined.center - truth.center)


def _second_camera():
    """A second camera, the default camera's lens, 15 cm to its left, aimed at TARGET."""
    cam = default_rig().camera
    return replace(cam, T_world_cam=look_at(cam.center - 0.15 * cam.T_world_cam[:3, 0], TARGET), name="camera 2")


@pytest.mark.parametrize("second", ["projector", "camera 2"])
def test_a_moved_second_device_returns_to_the_truth(second):
    rig = default_rig()
    cam, truth = rig.camera, (rig.projector if second == "projector" else _second_camera())
    uv1, uv2 = _pixels(_bumpy_sphere(cam, truth), cam, truth)
    given = _moved(truth, cam.center, mm=5.0 if second == "projector" else -5.0)      # camera 2 is on the left
    result = refine_extrinsics(cam, given, uv1, uv2)
    degrees, mm = _errors(result.second, truth)
    assert degrees < 0.04 and mm < 0.15, (degrees, mm, result.describe())
    assert result.before_px > 5 and result.after_px < 0.3, result.describe()
    assert result.n_points + result.n_rejected == 20_000 and result.n_rejected < 200
    given_degrees, given_mm = _errors(given, truth)
    assert abs(result.rotation_deg - given_degrees) < 0.04 and abs(result.translation_mm - given_mm) < 0.15
    baseline = np.linalg.norm(truth.center - cam.center)
    assert abs(np.linalg.norm(result.second.center - cam.center) - baseline) < 1e-12     # the baseline held
    assert np.array_equal(result.second.K, truth.K) and result.freed == ()
    assert result.second.name == truth.name and "->" in result.describe()


def test_wrong_decodes_do_not_drag_it():
    rig = default_rig()
    cam, truth = rig.camera, rig.projector
    uv1, uv2 = _pixels(_bumpy_sphere(cam, truth), cam, truth)
    wrong = np.random.default_rng(2).permutation(len(uv2))[:2000]                      # 10 %, anywhere in the image
    uv2[wrong] = np.random.default_rng(3).uniform((0, 0), truth.size, (len(wrong), 2))
    result = refine_extrinsics(cam, _moved(truth, cam.center), uv1, uv2)
    degrees, mm = _errors(result.second, truth)
    assert degrees < 0.04 and mm < 0.15, (degrees, mm, result.describe())
    assert 1800 < result.n_rejected < 2600, result.describe()


def test_a_freed_focal_length_returns_to_the_truth():
    rig = default_rig()
    cam, truth = rig.camera, rig.projector
    uv1, uv2 = _pixels(_bumpy_sphere(cam, truth), cam, truth)
    given = _moved(truth, cam.center)
    K = given.K.copy()
    K[[0, 1], [0, 1]] *= 1.01                                                           # 15 px
    result = refine_extrinsics(cam, replace(given, K=K), uv1, uv2, free_intrinsics=True)
    degrees, mm = _errors(result.second, truth)
    assert degrees < 0.05 and mm < 0.75, (degrees, mm, result.describe())
    assert np.all(np.abs(np.diag(result.second.K - truth.K)[:2]) < 3.0), result.second
    assert np.array_equal(result.second.K[:2, 2], truth.K[:2, 2])                    # cx, cy held
    assert result.freed == ("f",) and "f freed" in result.describe() and result.after_px < 0.3


def test_four_intrinsics_are_more_than_two_views_fix():
    """Two views fix 7 numbers; the pose takes 5: fx, fy, cx, cy beside it are refused, by name, on any object."""
    rig = default_rig()
    cam, truth = rig.camera, rig.projector
    uv1, uv2 = _pixels(_bumpy_sphere(cam, truth), cam, truth)
    with pytest.raises(CalibrationError, match=r"do not fix .*fx, fy, cx, cy: standard deviation"):
        refine_extrinsics(cam, truth, uv1, uv2, free_intrinsics=("fx", "fy", "cx", "cy"))


def test_what_the_data_cannot_support_is_refused():
    rig = default_rig()
    cam, proj = rig.camera, rig.projector
    uv1, uv2 = _pixels(_bumpy_sphere(cam, proj), cam, proj)
    with pytest.raises(CalibrationError, match=f"too few correspondences: 150 finite, at least {MIN_POINTS}"):
        refine_extrinsics(cam, proj, uv1[:150], uv2[:150])
    patch = np.all(np.abs(uv1 - (640, 512)) < 50, axis=1)                             # a 100 px square
    assert patch.sum() >= MIN_POINTS
    with pytest.raises(CalibrationError, match=r"degenerate spread: .*% of camera's image"):
        refine_extrinsics(cam, proj, uv1[patch], uv2[patch])
    flat1, flat2 = _pixels(_plane(), cam, proj)
    refine_extrinsics(cam, _moved(proj, cam.center), flat1, flat2)                        # a plane fixes the pose
    with pytest.raises(CalibrationError, match=r"do not fix .*\bf: standard deviation|do not fix .*; f \d"):
        refine_extrinsics(cam, _moved(proj, cam.center), flat1, flat2, free_intrinsics=True)
    with pytest.raises(InputError, match="free_intrinsics"):
        refine_extrinsics(cam, proj, uv1, uv2, free_intrinsics=("f", "fx"))
    with pytest.raises(InputError, match=r"\(N, 2\)"):
        refine_extrinsics(cam, proj, uv1, uv2[:-1])


def test_a_refinement_that_ends_no_better_is_refused(monkeypatch):
    rig = default_rig()
    cam, proj = rig.camera, rig.projector
    uv1, uv2 = _pixels(_bumpy_sphere(cam, proj), cam, proj)
    stuck = lambda model, first, a, b: (np.zeros(model.n), np.ones(len(a), dtype=bool), 1)   # noqa: E731
    monkeypatch.setattr(refine_module, "_fit", stuck)
    with pytest.raises(CalibrationError, match="ended no better than it started"):
        refine_extrinsics(cam, _moved(proj, cam.center), uv1, uv2)


def test_a_turned_projector_returns_from_a_decoded_capture(decoded_graycode):
    rig, dec = decoded_graycode
    turned = rig.projector.T_world_cam.copy()
    turned[:3, :3] = turned[:3, :3] @ axis_angle_to_R(np.array([1.0, 1.0, 0.3]), np.radians(0.5))
    given = rig.projector.with_pose(turned)
    assert not check_rig(rig.camera, given, dec.proj_col, dec.proj_row).fits
    ys, xs = np.nonzero(np.isfinite(dec.proj_col) & np.isfinite(dec.proj_row))
    uv_cam = np.column_stack([xs, ys]).astype(np.float64)
    uv_proj = np.column_stack([dec.proj_col[ys, xs], dec.proj_row[ys, xs]])
    result = refine_extrinsics(rig.camera, given, uv_cam, uv_proj)
    degrees, mm = _errors(result.second, rig.projector)
    assert degrees < 0.05 and mm < 0.5, (degrees, mm, result.describe())
    assert result.before_px > 2 and result.after_px < 0.1, result.describe()
    assert check_rig(rig.camera, result.second, dec.proj_col, dec.proj_row).fits
