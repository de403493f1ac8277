"""Shape fits the tests use to measure reconstructions against the simulator's known objects."""

from __future__ import annotations

import numpy as np


def fit_sphere(P: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares sphere through (N, 3) points: (centre (3,), radius), in the points' units.

    Algebraic fit, then Gauss-Newton on the point-to-sphere distances (the geometric fit).
    """
    P = np.asarray(P, dtype=np.float64)
    A = np.column_stack([2 * P, np.ones(len(P))])
    sol, *_ = np.linalg.lstsq(A, np.sum(P * P, axis=1), rcond=None)
    c = sol[:3]
    for _ in range(10):
        d = P - c
        r_i = np.linalg.norm(d, axis=1)
        J = np.column_stack([-d / r_i[:, None], -np.ones(len(P))])
        step, *_ = np.linalg.lstsq(J, -(r_i - r_i.mean()), rcond=None)
        c = c + step[:3]
    return c, float(np.linalg.norm(P - c, axis=1).mean())
