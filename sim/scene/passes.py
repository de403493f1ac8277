"""The simulator's multi-pass scans: the object turned over between turntable passes, by a known motion.

Pass 0 is the object as :func:`rangekit.sim.scene.scene.default_scene` stands it on the table. Before pass ``p``
the object is turned over: :func:`turn_over_motion` gives the rigid motion (world frame) from its pose in
pass 0, 180 degrees about a horizontal axis, then a turn about the table's axis and a small shift, and
lowered so it rests on the table top again. The session records these motions for the ground truth only
(``simulator.pass_motions``); processing finds the passes' relative pose from the data.
"""

from __future__ import annotations

import numpy as np

from rangekit.geometry import apply_T, axis_angle_to_R, compose, invert_T, make_T
from rangekit.rig.rig_file import Rig
from rangekit.sim.scene.scene import Scene

__all__ = ["TURN_OVER_YAW_RAD", "TURN_OVER_SHIFT_M", "turn_over_motion", "pass_motions", "pass_scene", "split_views",
           "view_motions"]

#: After the half-turn about the table's x axis, a turn about its z axis (radians) and a shift along the table
#: (metres): the second pass's pose is not the first's mirrored about an obvious axis.
TURN_OVER_YAW_RAD = 0.7
TURN_OVER_SHIFT_M = (0.004, -0.003)


def turn_over_motion(scene: Scene, rig: Rig, *, yaw: float = TURN_OVER_YAW_RAD,
                     shift: tuple[float, float] = TURN_OVER_SHIFT_M) -> np.ndarray:
    """(4, 4) the motion (world frame) that turns the scene's first object over on the table: in the table's
    frame, 180 degrees about x through the centre of the object's bounding box, then ``yaw`` about z, then
    the box centre moved by ``shift`` (x, y metres), and the lowest vertex put on the table top (z = 0)."""
    T_wt = rig.T_world_table if rig.T_world_table is not None else np.eye(4)
    V = apply_T(invert_T(T_wt), scene.objects[0].world_vertices())    # table frame
    c = (V.min(axis=0) + V.max(axis=0)) / 2
    R = axis_angle_to_R(np.array([0.0, 0.0, 1.0]), yaw) @ axis_angle_to_R(np.array([1.0, 0.0, 0.0]), np.pi)
    t = np.array([c[0] + shift[0], c[1] + shift[1], 0.0]) - R @ c
    t[2] = -(V @ R.T)[:, 2].min()
    return compose(T_wt, make_T(R, t), invert_T(T_wt))


def pass_motions(scene: Scene, rig: Rig, passes: int) -> np.ndarray:
    """(passes, 4, 4): the identity, then the object turned over (:func:`turn_over_motion`), turned back,
    over again...: pass ``p`` is turned over when ``p`` is odd."""
    F = turn_over_motion(scene, rig)
    return np.stack([F if p % 2 else np.eye(4) for p in range(passes)])


def pass_scene(scene: Scene, motion: np.ndarray) -> Scene:
    """The scene with its first object (the scanned one) moved by ``motion`` (4, 4, world); the table stays."""
    obj = scene.objects[0]
    return Scene((obj.with_pose(compose(np.asarray(motion, dtype=np.float64), obj.T_world_obj)),) + scene.objects[1:])


def split_views(angles, pass_motions=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(angles (n,), passes (n,) int, motions (P, 4, 4))`` of the views: ``angles`` are turntable angles
    (radians; one pass, motions the identity) or, with ``pass_motions``, ``(angle, pass)`` pairs."""
    if pass_motions is None:
        a = np.asarray(angles, dtype=np.float64).reshape(-1)
        return a, np.zeros(len(a), np.int64), np.eye(4)[None]
    pairs = np.asarray(angles, dtype=np.float64).reshape(-1, 2)
    return pairs[:, 0].copy(), pairs[:, 1].astype(np.int64), np.asarray(pass_motions, dtype=np.float64)


def view_motions(rig: Rig, angles, pass_motions=None) -> np.ndarray:
    """(n, 4, 4) how each view saw the object moved from its pose at table angle 0 in the first pass:
    the pass's turn-over, then the table's turn (``rig.T_world_rotated(angle) @ pass_motions[pass]``)."""
    a, vp, F = split_views(angles, pass_motions)
    return np.stack([(rig.T_world_rotated(float(x)) if rig.T_world_table is not None else np.eye(4)) @ F[p]
                     for x, p in zip(a, vp)])
