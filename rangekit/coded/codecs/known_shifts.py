"""The phase of frames whose phase steps are known but not necessarily equal, by least squares.

Model, per pixel: ``I_k = A + B cos(phi - d_k)`` for K >= 3 frames with steps ``d_k`` (radians). Written as
``I_k = A + C cos d_k + S sin d_k`` with ``C = B cos phi``, ``S = B sin phi``, it is linear in (A, C, S):
``(A, C, S) = pinv(M) I`` with the rows ``M_k = (1, cos d_k, sin d_k)``, one fixed (3, K) matrix for the
whole image, so each of A, C, S is a weighted sum of the frames. ``phi = atan2(S, C)`` in [0, 2 pi),
``B = hypot(C, S)``. For equal steps ``d_k = 2 pi k / K`` this is :func:`rangekit.coded.phase.phase_from_steps`;
for three frames it is exact whatever the steps (OpenCV's PSP formula ``atan2((1 - cos d)(I3 - I2),
sin d (2 I1 - I2 - I3))`` is the same for its 2 pi / 3 and biased for other steps).

A projector response ``p ** gamma`` bends the phase of 3 equal steps (either direction) by a known function
(:mod:`rangekit.coded.response`): :func:`corrected_phase` undoes it. It also makes the fitted ``B`` depend on
the phase (for gamma 2.2 and 3 steps, 0.35 to 0.64 of the white - black signal ``b`` instead of 0.5):
:func:`white_minus_black` gives ``b`` from ``B`` at the true phase.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from rangekit.coded.response import phase_correction
from rangekit.rig.projector_response import ProjectorResponse

__all__ = ["phase_known_shifts", "shift_weights", "corrected_phase", "white_minus_black"]


def shift_weights(shifts: Sequence[float]) -> np.ndarray:
    """(3, K) float64 ``pinv(M)``: row 0 gives A, row 1 C = B cos phi, row 2 S = B sin phi."""
    d = np.asarray(shifts, dtype=np.float64)
    M = np.stack([np.ones_like(d), np.cos(d), np.sin(d)], axis=1)
    return np.linalg.pinv(M)


def phase_known_shifts(frames: Sequence[np.ndarray], shifts: Sequence[float]
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(phi in [0, 2 pi), modulation B, offset A), each (H, W) float32, of ``frames`` (K arrays (H, W), any
    real dtype, converted one at a time) with phase steps ``shifts`` (K,) radians (module doc)."""
    P = shift_weights(shifts).astype(np.float32)
    A = np.zeros(frames[0].shape, np.float32)
    C, S = np.zeros_like(A), np.zeros_like(A)
    for k, f in enumerate(frames):
        f32 = np.asarray(f, dtype=np.float32)
        A += P[0, k] * f32
        C += P[1, k] * f32
        S += P[2, k] * f32
    phi = np.arctan2(S, C)
    phi[phi < 0] += np.float32(2 * np.pi)
    return phi, np.hypot(C, S), A


def corrected_phase(phi: np.ndarray, response: ProjectorResponse | None) -> np.ndarray:
    """``phi`` of three equal steps (2 pi / 3, either direction) mapped through the correction for
    ``response`` (:func:`rangekit.coded.response.phase_correction`); unchanged for None or gamma 1."""
    if response is None or response.is_linear:
        return phi
    return phase_correction(response, 3)(phi)


def white_minus_black(B: np.ndarray, phi: np.ndarray, shifts: Sequence[float],
                      response: ProjectorResponse | None) -> np.ndarray:
    """The white - black signal ``b`` of frames ``b g(0.5 + 0.5 cos(phi - d_k))`` whose fit gave modulation ``B``
    at the true phase ``phi`` (``g(p) = p ** gamma``, the ``response``): ``B`` divided by the modulation the fit
    gives for ``b = 1`` at that phase (1/2 for a linear projector), or by 1/2 where that is less (a smaller
    divisor would raise the noise of dark pixels above the linear case's; ``b`` is then underestimated, by up to
    30% for gamma 2.2). (H, W) float32."""
    if response is None or response.is_linear:
        return np.float32(2) * B
    P = shift_weights(shifts).astype(np.float32)
    C, S = np.zeros_like(B), np.zeros_like(B)
    for k, d in enumerate(shifts):
        g = np.power(np.float32(0.5) + np.float32(0.5) * np.cos(phi - np.float32(d)), np.float32(response.gamma))
        C += P[1, k] * g
        S += P[2, k] * g
    return (B / np.maximum(np.hypot(C, S), np.float32(0.5))).astype(np.float32)
