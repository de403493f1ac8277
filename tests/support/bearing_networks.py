"""Random bearing networks for the tests of rangekit.registration.bearings and benchmarks/registration/bench_bearings.py:
positions, a graph, exact and noisy relative translations, and the comparison with translation synchronisation."""

from __future__ import annotations

import numpy as np

from rangekit.geometry import make_T
from rangekit.registration import locate_from_bearings, synchronise_translations


def network(n: int, p: float, seed: int):
    """Random positions (n, 3) and a random graph on them (each pair an edge with probability p, a path
    through all nodes always), with their exact unit bearings."""
    rng = np.random.default_rng(seed)
    c = rng.standard_normal((n, 3))
    pairs = {(i, i + 1) for i in range(n - 1)} | {(i, j) for i in range(n) for j in range(i + 2, n) if rng.random() < p}
    edges = np.array(sorted(pairs))
    d = c[edges[:, 1]] - c[edges[:, 0]]
    return c, edges, d / np.linalg.norm(d, axis=1)[:, None]


def relative_error(c_est: np.ndarray, c_true: np.ndarray) -> float:
    """RMS distance after the best scale (both with node 0 at the origin), relative to the network's size."""
    a, b = c_est - c_est[0], c_true - c_true[0]
    s = np.sum(a * b) / np.sum(a * a)
    return float(np.sqrt(np.mean(np.sum((s * a - b) ** 2, axis=1))) / np.sqrt(np.mean(np.sum(b ** 2, axis=1))))


def noisy(c, edges, angle_deg: float, length_sd: float, rng):
    d = c[edges[:, 1]] - c[edges[:, 0]]
    axis = rng.standard_normal(d.shape)
    axis -= np.sum(axis * d, axis=1)[:, None] * d / np.sum(d * d, axis=1)[:, None]
    axis /= np.linalg.norm(axis, axis=1)[:, None]
    theta = np.radians(angle_deg) * rng.standard_normal(len(d))
    norm = np.linalg.norm(d, axis=1)[:, None]
    turned = np.cos(theta)[:, None] * d + np.sin(theta)[:, None] * norm * axis
    return turned * np.maximum(0.05, 1 + length_sd * rng.standard_normal(len(d)))[:, None]


def compare_with_translation_sync(angle_deg: float, length_sd: float, *, n: int = 30, p: float = 0.25,
                                  trials: int = 10, seed: int = 0) -> tuple[float, float]:
    """Median relative position error (bearings, translation synchronisation) over ``trials`` networks whose
    relative translations have ``angle_deg`` of direction noise and a relative length noise ``length_sd``
    (bearings see only the directions; synchronisation the whole vectors). Also used by docs/registration.md's
    table (benchmarks/registration/bench_bearings.py)."""
    rng = np.random.default_rng(seed)
    errors = []
    for k in range(trials):
        c, edges, _ = network(n, p, seed + 100 + k)
        t = noisy(c, edges, angle_deg, length_sd, rng)
        located = locate_from_bearings(t / np.linalg.norm(t, axis=1)[:, None], edges).positions
        synced = synchronise_translations(n, [(int(i), int(j), make_T(np.eye(3), v)) for (i, j), v in zip(edges, t)],
                                          np.repeat(np.eye(3)[None], n, axis=0), robust=False).t_world
        errors.append((relative_error(located, c), relative_error(synced, c)))
    return tuple(float(x) for x in np.median(errors, axis=0))
