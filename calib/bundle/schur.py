"""Levenberg-Marquardt on the reduced system (Fusiello 14.4): a bundle adjustment's normal equations solved through
the Schur complement on the shared parameters, each board pose eliminated by its own 6 x 6 block.

The parameters split into shared ones ``g`` (both devices' intrinsics, the projector's pose: a few tens) and one
6-vector per board pose ``p_k`` (rotation vector, translation), and a residual row depends on ``g`` and on one pose
only, so the Gauss-Newton matrix is ``[[U, W], [W^T, V]]`` with ``V`` block diagonal. Each step solves

    (U - sum_k W_k V_k^-1 W_k^T) dg = b_g - sum_k W_k V_k^-1 b_k,      dp_k = V_k^-1 (b_k - W_k^T dg)

with Marquardt's damping (``lambda`` times each matrix's diagonal added), accepted when the cost falls (then
``lambda`` / 10), else retried with ``lambda`` x 10. The Jacobian is never formed whole: ``J_g`` (rows x shared) and
``J_p`` (rows x 6, each row's own pose) are what the evaluation returns, rows grouped by pose.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

__all__ = ["ReducedSolution", "solve_reduced_lm"]


class ReducedSolution:
    """The solution: ``shared`` (n_g,), ``poses`` (n_poses, 6), ``cost`` (sum of squared residuals),
    ``iterations`` (accepted steps), ``evaluations`` (residual and Jacobian evaluations)."""

    def __init__(self, shared, poses, cost, iterations, evaluations):
        self.shared, self.poses, self.cost = shared, poses, cost
        self.iterations, self.evaluations = iterations, evaluations


def solve_reduced_lm(evaluate: Callable, shared0: np.ndarray, poses0: np.ndarray, starts: np.ndarray, *,
                     max_iterations: int = 200, xtol: float = 1e-12, ftol: float = 1e-15) -> ReducedSolution:
    """Minimise ``|r|^2`` over the shared parameters and the poses (module doc).

    ``evaluate(shared, poses, jacobian) -> (r (N,), J_g (N, n_g), J_p (N, 6))`` (the Jacobians None when
    ``jacobian`` is false: a trial step needs only its cost), rows grouped by pose: pose k owns rows
    ``starts[k]:starts[k + 1]`` (``starts`` (n_poses + 1,), increasing; every pose at least one row). Stops when a
    step changes every parameter by less than ``xtol`` relative (absolute near zero), or the cost by less than
    ``ftol`` relative, or after ``max_iterations`` accepted steps.
    """
    g, p = np.asarray(shared0, np.float64).copy(), np.asarray(poses0, np.float64).copy()
    seg = np.asarray(starts[:-1])
    r, Jg, Jp = evaluate(g, p, True)
    cost, evaluations, lam, iterations = float(r @ r), 1, 1e-5, 0
    eye6 = np.eye(6)
    while iterations < max_iterations:
        U, bg = Jg.T @ Jg, -Jg.T @ r
        V = np.add.reduceat(Jp[:, :, None] * Jp[:, None, :], seg, axis=0)          # (K, 6, 6)
        W = np.add.reduceat(Jg[:, :, None] * Jp[:, None, :], seg, axis=0)          # (K, n_g, 6)
        bp = np.add.reduceat(-Jp * r[:, None], seg, axis=0)                         # (K, 6)
        dU, dV = np.diag(U).copy(), np.einsum("kii->ki", V).copy()
        while True:
            Vinv = np.linalg.inv(V + lam * dV[:, :, None] * eye6)
            WV = W @ Vinv                                                          # (K, n_g, 6)
            S = U + np.diag(lam * dU) - np.einsum("kij,klj->il", WV, W)
            dg = np.linalg.solve(S, bg - np.einsum("kij,kj->i", WV, bp))
            dp = np.einsum("kij,kj->ki", Vinv, bp - np.einsum("kji,j->ki", W, dg))
            g_new, p_new = g + dg, p + dp
            r_new = evaluate(g_new, p_new, False)[0]
            evaluations += 1
            cost_new = float(r_new @ r_new)
            if cost_new < cost:
                break
            lam *= 10.0
            if lam > 1e16:
                return ReducedSolution(g, p, cost, iterations, evaluations)
        small = (np.all(np.abs(dg) <= xtol * (np.abs(g) + xtol)) and np.all(np.abs(dp) <= xtol * (np.abs(p) + xtol)))
        flat = cost - cost_new <= ftol * cost
        g, p, cost = g_new, p_new, cost_new
        r, Jg, Jp = evaluate(g, p, True)
        iterations += 1
        lam = max(lam / 10.0, 1e-15)
        if small or flat:
            break
    return ReducedSolution(g, p, cost, iterations, evaluations)
