"""Interreflection inside a concave object, removed only where its model is seen to hold.

The model (a spherical cavity). Inside a sphere every wall patch lights every point alike, so the light
one bounce adds under light i is ``albedo(x) * beta_i`` at every pixel, and ``beta_i`` is proportional
to the light entering the opening, linear in the light direction: ``beta_i = k . s_i``. A pixel in
cast shadow from light i sees only that term, so ``B / albedo`` there measures ``beta_i``.

Where it does not hold. Real objects have cast shadows too (under an ear, in a fold, at the foot of a
step), but the light in them comes from the nearest walls and differs from place to place, or only a
corner receives it. Subtracting one ``beta_i`` from every pixel then bends the normals of pixels that
received nothing: on three real DiLiGenT objects (issue 34's measurement; they are not in ../shared/data)
the mean error rose from 13.1 to 14.0 deg, and on the simulator's bunny, steps and thin objects from 4.4 to
4.9, 8.5 to 14.7 and 23.8 to 25.9 deg.

So :func:`cavity_light` measures ``beta`` and applies it only if the shadows show the model:

1. ``spread``: for each light, the interquartile range of ``B / albedo`` over its shadowed pixels, over
   its median; the median over lights must be at most ``MAX_SPREAD`` (one value for every pixel). The
   simulated bowl: 0.13; bunny 5.3, thin 1.2.
2. ``misfit``: the RMS of ``beta_i - k . s_i`` over the RMS of ``beta_i`` at most ``MAX_MISFIT`` (linear in
   the light). Bowl: 0.022; bunny 0.71, thin 0.36.
3. ``coverage``: the fraction of the object's pixels in cast shadow from some measured light, at least
   ``MIN_COVERAGE`` (the term is claimed for every pixel: it must be seen over much of the object, not in a
   corner). Bowl: 0.50; steps 0.15.

Figures from ``python benchmarks/photometric/bench_cavity_light.py`` (48 lights, 160 x 128 pixels).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["CavityLight", "cavity_light", "MAX_SPREAD", "MAX_MISFIT", "MIN_COVERAGE", "MIN_LIGHTS"]

MAX_SPREAD = 0.5     # interquartile range / median of B / albedo in one light's shadows (bowl 0.13)
MAX_MISFIT = 0.1     # relative RMS of beta about its linear fit in the light direction (bowl 0.022)
MIN_COVERAGE = 0.3   # fraction of pixels shadowed from some measured light (bowl 0.50, steps 0.15)
MIN_LIGHTS = 6       # lights with enough cast shadow to fit k (3 unknowns) with some redundancy


@dataclass(frozen=True, eq=False)
class CavityLight:
    """What :func:`cavity_light` measured and whether the correction applies."""

    beta: np.ndarray     # (f,) light each image adds in proportion to the albedo; zeros when not applied
    applied: bool
    lights: int          # lights with enough cast shadow to measure beta on
    spread: float        # criterion 1 (nan when not measured)
    misfit: float        # criterion 2
    coverage: float      # criterion 3

    def describe(self) -> str:
        """One line for the result and the command's output."""
        if self.lights < MIN_LIGHTS:
            return (f"interreflection correction not applied: {self.lights} lights cast enough shadow to measure it "
                    f"on, {MIN_LIGHTS} needed (a convex object: nothing to correct)")
        figures = (f"spread {self.spread:.2f} (<= {MAX_SPREAD:g}), misfit {self.misfit:.3f} (<= {MAX_MISFIT:g}), "
                   f"coverage {self.coverage:.2f} (>= {MIN_COVERAGE:g}) over {self.lights} lights")
        if self.applied:
            return f"interreflection of a concave object removed (spherical-cavity model holds: {figures})"
        return f"interreflection correction not applied: its spherical-cavity model does not hold ({figures})"


def cavity_light(B: np.ndarray, rho: np.ndarray, shadow: np.ndarray, S: np.ndarray, *, min_pixels: int = 20,
                 min_fraction: float = 0.02, force: bool = False) -> CavityLight:
    """Measure the cavity term of (p, f) intensities ``B`` and decide whether it applies.

    ``rho`` (p,) albedo of the current fit; ``shadow`` (p, f) bool, pixel p in cast shadow from light i;
    ``S`` (3, f) light directions. ``beta_i`` is the median of ``B / rho`` over the pixels shadowed from
    light i, on lights that shadow at least ``min_pixels`` pixels and ``min_fraction`` of them; ``k`` (3,)
    is fitted to them by least squares. ``beta = max(k . S, 0)`` when the three criteria of the module
    docstring hold (or ``force``: measured and applied whatever they say, for comparisons), else zeros.
    """
    f = B.shape[1]
    counts = shadow.sum(axis=0)
    measured = np.flatnonzero(counts >= max(min_pixels, min_fraction * len(B)))
    if measured.size < MIN_LIGHTS:
        return CavityLight(np.zeros(f), False, int(measured.size), np.nan, np.nan, np.nan)
    sub = shadow[:, measured] & (rho[:, None] > 0)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.where(sub, B[:, measured] / rho[:, None], np.nan)
    beta = np.nanmedian(ratio, axis=0)
    q25, q75 = np.nanpercentile(ratio, [25, 75], axis=0)
    spread = float(np.median((q75 - q25) / np.maximum(np.abs(beta), 1e-12)))
    k = np.linalg.lstsq(S[:, measured].T, beta, rcond=None)[0]
    misfit = float(np.sqrt(np.mean((beta - k @ S[:, measured]) ** 2)) / max(np.sqrt(np.mean(beta ** 2)), 1e-300))
    coverage = float(shadow[:, measured].any(axis=1).mean())
    applied = force or (spread <= MAX_SPREAD and misfit <= MAX_MISFIT and coverage >= MIN_COVERAGE)
    return CavityLight(np.maximum(k @ S, 0.0) if applied else np.zeros(f), bool(applied), int(measured.size),
                       spread, misfit, coverage)
