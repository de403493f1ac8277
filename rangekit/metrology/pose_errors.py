"""How far estimated poses are from reference poses (e.g. a registration against Stanford's ``.conf``).

Both sets are first expressed in their own first view's frame (``inv(T[0]) @ T``), as registration
puts its world there, so two sets that differ only by the choice of world agree exactly.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.spatial.transform import Rotation

from rangekit.geometry import invert_T

__all__ = ["PoseErrors", "pose_errors"]


class PoseErrors(NamedTuple):
    rotation_deg: np.ndarray    # (n,) angle of R_est R_true^T, degrees (view 0: 0)
    translation_m: np.ndarray   # (n,) |t_est - t_true|, metres, in the first view's frame


def pose_errors(T_est: np.ndarray, T_true: np.ndarray) -> PoseErrors:
    """Per-view errors of ``T_est`` against ``T_true``, both (n, 4, 4) ``T_world_view``."""
    A = np.einsum("ij,njk->nik", invert_T(np.asarray(T_est, float)[0]), np.asarray(T_est, float))
    B = np.einsum("ij,njk->nik", invert_T(np.asarray(T_true, float)[0]), np.asarray(T_true, float))
    rot = np.degrees(Rotation.from_matrix(A[:, :3, :3] @ np.transpose(B[:, :3, :3], (0, 2, 1))).magnitude())
    return PoseErrors(rot, np.linalg.norm(A[:, :3, 3] - B[:, :3, 3], axis=1))
