"""A scan's blocks volume filled ahead in its own child process (issue 51 M7,
:class:`rangekit.app.process.blocks.BlocksAhead`): its surface is the bytes :func:`blocks_surface` makes in this
process from the same views; a view out of order ends the filling and its child. The views: the depth of a sphere
on the turntable's axis seen by the small rig's camera at four turntable angles (its surface then a sphere of that
radius: checked against it, so an empty or misplaced surface fails too)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from rangekit.app.process.blocks import BLOCKS_VOXEL_M, BlocksAhead, blocks_surface, prior_pose
from rangekit.geometry import apply_T, compose, invert_T
from support.small_rigs import small_rig

ANGLES = np.deg2rad([0.0, 90.0, 180.0, 270.0])
RADIUS = 0.02


def _sphere_depth(camera, centre_cam: np.ndarray) -> np.ndarray:
    """(H, W) camera-frame z (metres) of the near side of a sphere of :data:`RADIUS` at ``centre_cam``; NaN off it."""
    u, v = np.meshgrid(np.arange(camera.width, dtype=np.float64), np.arange(camera.height, dtype=np.float64))
    rays = np.stack([u, v, np.ones_like(u)], axis=-1) @ np.linalg.inv(camera.K).T      # z = 1
    b = rays @ centre_cam
    a = np.einsum("hwi,hwi->hw", rays, rays)
    disc = b * b - a * (centre_cam @ centre_cam - RADIUS ** 2)
    with np.errstate(invalid="ignore"):
        return np.where(disc > 0, (b - np.sqrt(disc)) / a, np.nan)


def _views(rig):
    centre = rig.T_world_table[:3, 3] + 0.02 * rig.T_world_table[:3, 2]    # on the axis, above the table
    depths = []
    for angle in ANGLES:
        T_world_cam = compose(prior_pose(rig, ANGLES[0], angle), rig.camera.T_world_cam)
        depths.append(_sphere_depth(rig.camera, apply_T(invert_T(T_world_cam), centre[None])[0]))
    return centre, depths


def test_the_volume_filled_in_its_child_is_the_one_filled_here():
    rig = small_rig()
    centre, depths = _views(rig)
    ahead = BlocksAhead(rig, ANGLES[0])
    assert ahead._child is not None                      # the volume in a child process of its own
    for k in range(2):
        ahead.add(k, depths[k], ANGLES[k])
    assert ahead.send_now(2, depths[2], ANGLES[2])      # a last view, sent to the child as it is decoded
    ahead.finish([(3, depths[3], ANGLES[3])])
    assert ahead._child is None and not ahead.broken
    poses = np.stack([prior_pose(rig, ANGLES[0], a) for a in ANGLES])
    here, _ = blocks_surface([SimpleNamespace(depth=d) for d in depths], poses, rig)
    there = ahead.surface_of([0, 1, 2, 3])
    assert ahead.taken and len(there.triangles) > 1000
    assert there.vertices.tobytes() == here.vertices.tobytes() and there.triangles.tobytes() == here.triangles.tobytes()
    r = np.linalg.norm(there.vertices - centre, axis=1)
    # the sphere: half its vertices within half a voxel (measured median 0.19 mm; the rest the rims carried 4 px
    # past each view's silhouette on the small rig's 320 x 256 camera, which the observed cut trims in a fusion)
    assert np.median(np.abs(r - RADIUS)) < BLOCKS_VOXEL_M / 2


def test_a_view_out_of_order_ends_the_filling_and_its_child():
    rig = small_rig()
    _, depths = _views(rig)
    ahead = BlocksAhead(rig, ANGLES[0])
    child = ahead._child
    ahead.add(1, depths[1], ANGLES[1])
    assert ahead.broken and ahead._child is None and child._proc.returncode is not None
    ahead.finish([])
    assert ahead.surface_of([1]) is None and not ahead.taken
