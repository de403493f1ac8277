"""A camera-projector bundle adjustment problem with exact truth, for tests/calib/test_bundle_schur.py and
benchmarks/calib/bench_bundle.py."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from rangekit.boards import Board
from rangekit.calib.bundle.problem import intrinsics_vector as _intr_vector
from rangekit.calib.projection_jacobian import project as _project
from rangekit.geometry import R_to_rotvec, make_T, rotvec_to_R


def bundle_problem(n_poses: int, seed: int = 0, noise_px: float = 0.03):
    """A camera-projector calibration problem on the simulator's true rig: ``n_poses`` hand-held board poses,
    every corner seen by both devices with ``noise_px`` of noise, and a perturbed starting point."""
    from rangekit.sim import default_rig
    from rangekit.sim.writers.calibration import board_poses

    truth = default_rig()
    board = Board()
    obj = board.object_points()
    rng = np.random.default_rng(seed)
    T_cam_world = truth.camera.T_cam_world
    T_proj_cam = truth.projector.T_cam_world @ truth.camera.T_world_cam
    poses = {k: T_cam_world @ T for k, T in enumerate(board_poses(truth, board, n_poses, seed=seed))}
    ids = np.arange(len(obj))
    cam_obs, proj_obs = {}, {}
    for k, T in poses.items():
        Pc = obj @ T[:3, :3].T + T[:3, 3]
        Pp = Pc @ T_proj_cam[:3, :3].T + T_proj_cam[:3, 3]
        cam_obs[k] = (ids, _project(Pc, _intr_vector(truth.camera), 0.0) + noise_px * rng.standard_normal((len(ids), 2)))
        proj_obs[k] = (ids, _project(Pp, _intr_vector(truth.projector), 0.0) + noise_px * rng.standard_normal((len(ids), 2)))

    def nudged(T, deg, m):
        return make_T(rotvec_to_R(R_to_rotvec(T[:3, :3]) + np.radians(deg) * rng.standard_normal(3)),
                      T[:3, 3] + m * rng.standard_normal(3))

    K = lambda dev, s: np.diag([1 + s, 1 + s, 1.0]) @ dev.K     # noqa: E731
    cam0 = replace(truth.camera, K=K(truth.camera, 0.01), dist=np.zeros(5))
    proj0 = replace(truth.projector, K=K(truth.projector, -0.01), dist=np.zeros(5))
    start = dict(camera=cam0, projector=proj0, T_proj_cam=nudged(T_proj_cam, 0.5, 0.002),
                 T_cam_board={k: nudged(T, 0.5, 0.002) for k, T in poses.items()}, object_points=obj,
                 cam_obs=cam_obs, proj_obs=proj_obs)
    return truth, T_proj_cam, poses, start
