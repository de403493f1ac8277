"""Localisation from bearings against translation synchronisation on the same noisy networks (issue 38 item 4):
the median relative position error of each, over a grid of direction and length noise (docs/registration.md).

    .venv/bin/python benchmarks/registration/bench_bearings.py          # markdown table, about 10 s

Each trial: 30 random positions, a path through them plus each other pair with probability 0.25; each relative
translation turned by Gaussian direction noise and scaled by Gaussian length noise. Bearings get the directions
only; translation synchronisation (rangekit.registration.synchronise_translations, non-robust least squares,
rotations known) the whole vectors. Errors: RMS after the best scale, over the network's RMS size; median of 10.
"""

from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tests"))

from support.bearing_networks import compare_with_translation_sync  # noqa: E402


def main() -> None:
    print("| direction noise | length noise | bearings | translation synchronisation | better |")
    print("|---|---|---|---|---|")
    for angle in (0.5, 2.0):
        for length in (0.0, 0.05, 0.2, 0.5):
            b, t = compare_with_translation_sync(angle, length)
            print(f"| {angle:g} deg | {100 * length:g}% | {100 * b:.2f}% | {100 * t:.2f}% | "
                  f"{'bearings' if b < t else 'synchronisation'} |")


if __name__ == "__main__":
    main()
