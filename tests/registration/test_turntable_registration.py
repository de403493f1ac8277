"""Registration inside the turntable family: every view a rotation about one common axis."""

import numpy as np
import pytest

from rangekit.geometry import apply_T, axis_angle_to_R, invert_T, make_T, rotation_angle, rotvec_to_R
from rangekit.registration.multiview import MultiViewOptions, register_views
from rangekit.registration.turntable import common_axis, onto_turntable, turntable_basis
from rangekit.sim.writers.scans import perturb_poses, turntable_scans


def _about(axis, point, angle):
    R = axis_angle_to_R(axis, angle)
    return make_T(R, point - R @ point)


def _poses(n=8):
    axis = np.array([0.05, -0.1, 1.0]) / np.linalg.norm([0.05, -0.1, 1.0])
    point = np.array([0.01, -0.02, 0.0])
    point -= axis * (axis @ point)
    return axis, point, np.array([_about(axis, point, a) for a in 2 * np.pi * np.arange(n) / n])


def test_common_axis_and_projection_recover_the_axis_exactly():
    axis, point, T = _poses()
    a, o = common_axis(T)
    assert abs(a @ axis) > 1 - 1e-12 and np.allclose(o, point, atol=1e-12)   # the axis up to its sign
    assert np.allclose(onto_turntable(T), T, atol=1e-12)
    # A pose off the family (a tilt of 0.1 deg, 0.2 mm aside) comes back to its angle about the axis.
    bent = T.copy()
    bent[3] = make_T(rotvec_to_R([0.0017, 0, 0]), [2e-4, 0, 0]) @ T[3]
    assert np.degrees(rotation_angle(onto_turntable(bent)[3][:3, :3] @ T[3][:3, :3].T)) < 0.06


def test_the_basis_moves_poses_only_within_the_family():
    axis, point, T = _poses()
    centre, length = np.array([0.0, 0.0, 0.05]), 0.1
    B = turntable_basis(T, centre, length)
    assert B.shape == (6 * 7, 7 + 4)   # one angle per view, 4 for the axis
    # A small step along the basis: the poses stay rotations about one axis to second order.
    xi = B @ (np.random.default_rng(0).normal(size=B.shape[1]) * 1e-4)
    moved = T.copy()
    for k in range(1, len(T)):
        om, v = xi[6 * (k - 1): 6 * k - 3], xi[6 * k - 3: 6 * k]
        R = rotvec_to_R(om)
        moved[k] = make_T(R, v + centre - R @ centre) @ T[k]
    off = max(np.linalg.norm(m[:3, 3] - p[:3, 3]) + rotation_angle(m[:3, :3] @ p[:3, :3].T) * length
              for m, p in zip(moved, onto_turntable(moved)))
    step = np.abs(xi).max()
    assert off < 1e-3 * step, (off, step)
    # A step off the family (a translation of view 1 alone along the axis) is not in the span.
    e = np.zeros(6 * 7)
    e[3:6] = axis
    assert np.linalg.norm(e - B @ (B.T @ e)) > 0.5


@pytest.mark.slow     # 18 s: make test-slow (CI) runs it
def test_a_step_gauge_registers_on_the_turntable_where_free_poses_slide():
    scans = turntable_scans("steps", n_views=12, resolution=(480, 384), noise=0.0002)
    prior = perturb_poses(scans.T_world_view, max_angle=np.radians(0.3), max_translation=0.0005, rng=1)
    centre = scans.object_vertices.mean(axis=0)

    def worst(T):
        D = [T[k] @ invert_T(scans.T_world_view[k]) for k in range(len(T))]
        return (max(np.degrees(rotation_angle(d[:3, :3])) for d in D),
                max(np.linalg.norm(apply_T(d, centre[None])[0] - centre) for d in D))

    rot, move = worst(register_views(scans.clouds, init_T_world_view=prior,
                                     options=MultiViewOptions(turntable=True)).T_world_view)
    assert rot < 0.01 and move < 0.02e-3, (rot, move)
    free_rot, free_move = worst(register_views(scans.clouds, init_T_world_view=prior).T_world_view)
    assert free_move > 10 * move, (free_rot, free_move)
