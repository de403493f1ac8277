"""Issue 16, point 7: ``rangekit sim render --sensor tof`` + ``rangekit tof`` (default scene, 16/80/120 MHz,
320x240): at least 99.9% of the decoded pixels within 10 cm of the truth, at a coverage of at least 97%.

The 0.12-0.13% (issue: 0.11%) that used to miss were not wrong wraps but mixed pixels at depth edges whose centre ray
sees the far panel while a near panel, covering less than half of the pixel, sends 30-100x more light
(1/r^2): the pixel measured the near panel, consistently at every frequency. ``mixed_pixels`` (partial
coverage: less than half the brightness of the same surface next to a depth edge) now removes them.

Decoded = finite range in ``range.npy``; with truth = also finite in ``ground_truth.npz``'s ``range``;
coverage = pixels decoded among those the truth calls valid (hit and not mixed) over the truth-valid ones.
"""

from __future__ import annotations

import numpy as np
import pytest


def _figures(raw, out) -> tuple[float, float, int]:
    truth = np.load(raw / "ground_truth.npz")
    rng = np.load(out / "range.npy")
    decoded = np.isfinite(rng)
    both = decoded & np.isfinite(truth["range"])
    within = np.abs(rng - truth["range"])[both] <= 0.10
    coverage = (decoded & truth["valid"]).sum() / truth["valid"].sum()
    return within.mean(), coverage, int(both.sum())


def _run(cli_main, tmp_path, seed: int):
    raw, out = tmp_path / f"raw{seed}", tmp_path / f"out{seed}"
    assert cli_main(["sim", "render", "--sensor", "tof", "--seed", str(seed), "--out", str(raw)]) == 0
    assert cli_main(["tof", str(raw), "--out", str(out)]) == 0
    return _figures(raw, out)


def _check(seed, within, coverage, n):
    print(f"seed {seed}: {within:.4%} of {n} decoded pixels within 10 cm, coverage {coverage:.3%}")
    assert n > 70_000
    assert within >= 0.999, f"seed {seed}: only {within:.4%} within 10 cm"  # measured 99.975-99.985%
    assert coverage >= 0.97, f"seed {seed}: coverage {coverage:.3%}"        # measured 99.94%


def test_default_tof_scene_right_wrap_and_coverage(tmp_path):
    from rangekit.cli import main

    _check(0, *_run(main, tmp_path, 0))


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2, 3, 4])
def test_default_tof_scene_other_seeds(tmp_path, seed):
    from rangekit.cli import main

    _check(seed, *_run(main, tmp_path, seed))


def test_partial_pixels_flags_dim_edge_pixels_only():
    """A near panel (1 m) beside a far one (8 m), both of brightness A r^2 = 100 when fully covered: the
    edge column reporting 1 m at 30% brightness is flagged, at 70% kept; a dark stripe on one surface
    (an albedo edge, no depth edge) is kept."""
    from rangekit.tof import partial_pixels

    r = np.array([[1.0, 1.0, 1.0, 1.0, 8.0, 8.0]] * 5)
    b = np.full(r.shape, 100.0)
    b[:, 3] = 30.0            # near panel covering 30% of these pixels: centre on the far panel
    b[2, 3] = 70.0            # 70%: centre on the near panel
    b[:, 1] = 30.0            # albedo stripe inside the near panel
    A = np.stack([b / r ** 2] * 3)  # three frequencies
    flagged = partial_pixels(r, A)
    expected = np.zeros(r.shape, bool)
    expected[:, 3] = True
    expected[2, 3] = False
    np.testing.assert_array_equal(flagged, expected)
    assert not partial_pixels(r, A, min_fill=0.25).any()
    r_nan = r.copy()
    r_nan[0, 0] = np.nan
    assert not partial_pixels(r_nan, A)[0, 0]


def test_partial_pixels_are_reported_and_can_be_kept(tmp_path, capsys):
    from rangekit.cli import main

    raw = tmp_path / "raw"
    assert main(["sim", "render", "--sensor", "tof", "--size", "160x120", "--out", str(raw)]) == 0
    assert main(["tof", str(raw), "--out", str(tmp_path / "a")]) == 0
    assert "partial 0." in capsys.readouterr().out
    assert main(["tof", str(raw), "--out", str(tmp_path / "b"), "--keep-flying"]) == 0
    kept, filtered = np.load(tmp_path / "b" / "range.npy"), np.load(tmp_path / "a" / "range.npy")
    assert np.isfinite(kept).sum() > np.isfinite(filtered).sum()
