"""Projector coordinates of board corners by local homographies (rangekit.calib.local_homography): exact on a
plane's homography, robust to the decoder's wrong pixels, blind to the masked ones, and NaN where a corner's
window holds too few decoded pixels."""

from __future__ import annotations

import numpy as np

from rangekit.calib.local_homography import local_homography_coords

H_TRUE = np.array([[1.3, 0.2, 40.0], [-0.1, 1.1, 25.0], [2e-4, -1e-4, 1.0]])   # camera px -> projector px


def _maps(shape=(200, 300)):
    yy, xx = np.mgrid[0:shape[0], 0:shape[1]].astype(np.float64)
    den = H_TRUE[2, 0] * xx + H_TRUE[2, 1] * yy + H_TRUE[2, 2]
    return ((H_TRUE[0, 0] * xx + H_TRUE[0, 1] * yy + H_TRUE[0, 2]) / den,
            (H_TRUE[1, 0] * xx + H_TRUE[1, 1] * yy + H_TRUE[1, 2]) / den)


def _truth(uv):
    p = np.column_stack([uv, np.ones(len(uv))]) @ H_TRUE.T
    return p[:, :2] / p[:, 2:]


def test_an_exact_homography_is_recovered_at_subpixel_corners():
    col, row = _maps()
    uv = np.random.default_rng(0).uniform([12, 12], [288, 188], (50, 2))
    fit = local_homography_coords(col.astype(np.float32), row.astype(np.float32), uv)
    assert fit.ok.all() and (fit.n_pixels == 441).all()
    assert np.abs(fit.proj_uv - _truth(uv)).max() < 2e-3                  # float32 maps: 1e-5 relative


def test_wrong_pixels_are_outvoted_and_masked_ones_left_out():
    """0.3 px of noise, 10% of the pixels a whole fine period (114 px) off, 20% masked: the estimates stay
    within a few hundredths of a pixel and the predicted standard error is the right size."""
    rng = np.random.default_rng(1)
    col, row = _maps()
    col, row = col + rng.normal(0, 0.3, col.shape), row + rng.normal(0, 0.3, row.shape)
    wrong = rng.random(col.shape) < 0.1
    col[wrong] += rng.choice([-114.0, 114.0], wrong.sum())
    masked = rng.random(col.shape) < 0.2
    col[masked] = np.nan
    uv = rng.uniform([12, 12], [288, 188], (200, 2))
    fit = local_homography_coords(col.astype(np.float32), row.astype(np.float32), uv)
    err = fit.proj_uv - _truth(uv)
    assert fit.ok.all()
    assert np.sqrt(np.mean(err ** 2)) < 0.03 and np.abs(err).max() < 0.1  # measured 0.021, 0.074 px
    assert 0.5 < np.median(fit.std) / np.sqrt(np.mean(err ** 2)) < 1.5     # measured 0.8
    assert np.mean(fit.n_pixels) < 441 * 0.8 * 0.92                         # masked and wrong pixels dropped


def test_a_corner_outside_the_decoded_area_is_nan_not_an_extrapolation():
    """The projector's light ends at column 150: a corner 5 px beyond it has 105 decoded pixels in its window,
    all on one side, and is not estimated; nor one with none; one near the image's edge, surrounded, is."""
    col, row = _maps()
    col[:, 150:] = np.nan
    uv = np.array([[100.0, 100.0], [155.0, 100.0], [298.0, 5.0], [3.0, 3.0]])
    fit = local_homography_coords(col, row, uv, min_pixels=50)
    assert fit.ok.tolist() == [True, False, False, True]
    assert np.isnan(fit.proj_uv[1:3]).all() and np.isnan(fit.std[1:3]).all()
    assert fit.n_pixels[1] == 21 * 5 and fit.n_pixels[2] == 0
    assert np.abs(fit.proj_uv[3] - _truth(uv[3:])[0]).max() < 1e-6
    empty = local_homography_coords(col, row, np.zeros((0, 2)))
    assert empty.proj_uv.shape == (0, 2)
