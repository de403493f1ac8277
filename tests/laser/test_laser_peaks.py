"""Laser-line peak detection against synthetic lines with exactly known centres.

Frames from tests/support/laser_lines.py: pixel-integrated Gaussian profiles (1/e^2 widths 3-8 px) at a known
subpixel column per row (or a known slanted or curved line for the ridge detector), Gaussian noise,
8-bit quantisation, and a laser-off frame with its own noise.
"""

from __future__ import annotations

import numpy as np
import pytest

from support.laser_lines import circle, curve_line, row_line, slanted
from rangekit.errors import DecodeError, InputError
from rangekit.laser.peaks import (STATUS_DOUBLE, STATUS_OK, STATUS_SATURATED, STATUS_WEAK, detect_peaks,
                                  estimate_noise, laser_difference, require_peaks)

H, W = 240, 200
V = np.arange(H)
CENTRES = 95.0 + 30.0 * np.sin(V / 45.0) + 0.013 * V    # smoothly varying, every subpixel phase


def _ridge_row_errors(p, centres):
    """Distance from ridge points to the per-row centre curve, along the curve's normal (px)."""
    c = np.interp(p.points[:, 1], V, centres)
    slope = np.interp(p.points[:, 1], V, np.gradient(centres))
    return (p.points[:, 0] - c) / np.sqrt(1.0 + slope ** 2)


@pytest.mark.parametrize("width", [3.0, 5.0, 8.0])
@pytest.mark.parametrize("noise", [1.0, 2.0])
def test_subpixel_accuracy_of_each_method(width, noise):
    on, off = row_line(CENTRES, width, 200.0, W=W, noise=noise, seed=int(width * 10 + noise))
    rms = {}
    for method in ("argmax", "com", "gaussian"):
        p = detect_peaks(on, off, method=method)
        assert len(p) == H and np.all(p.status == STATUS_OK)
        err = p.columns() - CENTRES
        rms[method] = float(np.sqrt(np.mean(err ** 2)))
        assert abs(err.mean()) < 0.02, (method, err.mean())         # all unbiased on average over phases
        assert np.allclose(p.points[:, 1], V)
    ridge = detect_peaks(on, off, method="ridge")
    assert len(ridge) >= H - 10
    rms["ridge"] = float(np.sqrt(np.mean(_ridge_row_errors(ridge, CENTRES) ** 2)))
    assert rms["gaussian"] <= 0.05 and rms["ridge"] <= 0.05, rms
    assert rms["com"] <= 0.08, rms
    assert rms["argmax"] > 0.25 > 4 * max(rms["gaussian"], rms["ridge"]), rms
    g = detect_peaks(on, off, method="gaussian")
    assert np.median(g.width) == pytest.approx(width, rel=0.15)      # the 1/e^2 width is measured
    assert np.median(g.height) == pytest.approx(200.0, rel=0.08)
    assert np.median(ridge.width) == pytest.approx(width, rel=0.25)


@pytest.mark.parametrize("angle", [25.0, 50.0, 80.0])
def test_ridge_finds_slanted_lines_to_a_twentieth_of_a_pixel(angle):
    dist = slanted(angle, 100.3, 60.7)
    on, off = curve_line(dist, 120, 200, 4.0, 200.0, noise=1.5, seed=int(angle))
    p = detect_peaks(on, off, method="ridge")
    err = dist(p.points[:, 0], p.points[:, 1])
    assert np.sqrt(np.mean(err ** 2)) <= 0.05
    inside = 120 * min(1.0 / np.cos(np.radians(angle)), 200 / 120)   # px of line in the frame (roughly)
    assert len(p) >= 0.6 * inside                                    # about one point per pixel crossed
    # a row method on a nearly horizontal line cannot do this: a row holds the line over many pixels,
    # which the double-peak test refuses rather than returning a point somewhere along it
    if angle == 80.0:
        g = detect_peaks(on, off, method="gaussian")
        assert len(g) < 0.2 * len(p) and g.rejected["double"] > 0


def test_ridge_follows_a_curved_line():
    dist = circle(40.0, 80.0, 110.0)
    on, off = curve_line(dist, 160, 200, 4.0, 200.0, noise=1.5, seed=3)
    p = detect_peaks(on, off, method="ridge")
    err = dist(p.points[:, 0], p.points[:, 1])
    assert len(p) > 150 and np.sqrt(np.mean(err ** 2)) <= 0.05


def _add_line(on, centres, width, height):
    extra, _ = row_line(centres, width, height, W=on.shape[1], noise=0.0, background=0.0)
    return np.clip(on.astype(int) + extra, 0, 255).astype(np.uint8)


def test_double_peaks_are_rejected_and_weak_reflections_kept():
    on, off = row_line(CENTRES, 4.0, 200.0, W=W, noise=1.0, seed=5)
    second = np.where((V >= 50) & (V < 100), CENTRES + 40.0, np.nan)     # a strong interreflection
    faint = np.where((V >= 150) & (V < 200), CENTRES - 40.0, np.nan)     # a faint one (0.2 of the line)
    on = _add_line(_add_line(on, second, 4.0, 150.0), faint, 4.0, 40.0)
    p = detect_peaks(on, off, method="gaussian")
    assert np.all(p.status[50:100] == STATUS_DOUBLE) and np.all(np.isnan(p.columns()[50:100]))
    assert np.all(p.status[150:200] == STATUS_OK) and p.rejected["double"] == 50
    assert np.sqrt(np.nanmean((p.columns() - CENTRES) ** 2)) <= 0.05
    r = detect_peaks(on, off, method="ridge")
    assert not np.any((r.points[:, 1] > 51) & (r.points[:, 1] < 98)) and r.rejected["double"] > 50
    assert np.sum((r.points[:, 1] > 151) & (r.points[:, 1] < 198)) >= 45
    kept = detect_peaks(on, off, method="gaussian", double_ratio=None)
    assert np.all(kept.status[50:100] == STATUS_OK)


def test_saturated_peaks_are_flagged_and_the_frame_refused():
    heights = np.where(V < 120, 200.0, 400.0)                          # the lower half clipped at 255
    on, off = row_line(CENTRES, 5.0, heights, W=W, noise=1.0, seed=6)
    for method in ("gaussian", "com"):
        p = detect_peaks(on, off, method=method)
        assert np.all(p.status[:120] == STATUS_OK) and np.all(p.status[125:] == STATUS_SATURATED)
    r = detect_peaks(on, off, method="ridge")
    assert r.rejected["saturated"] > 100 and np.all(r.points[:, 1] < 126)
    on_all, off_all = row_line(CENTRES, 5.0, 400.0, W=W, noise=1.0, seed=7)
    with pytest.raises(DecodeError, match=r"step 12 laser1: found 0 line peaks.*240 saturated.*lower the laser"):
        require_peaks(detect_peaks(on_all, off_all), "step 12 laser1")
    # 16-bit images saturate at 65535 unless told otherwise
    p16 = detect_peaks(on.astype(np.uint16) * 257, off.astype(np.uint16) * 257)
    assert np.all(p16.status[125:] == STATUS_SATURATED)
    assert np.all(detect_peaks(on, off, saturation=1000).status == STATUS_OK)


def test_rows_without_line_are_nan_and_a_black_frame_is_an_error():
    centres = np.where((V > 80) & (V < 140), np.nan, CENTRES)
    on, off = row_line(centres, 4.0, 200.0, W=W, noise=1.0, seed=8)
    for method in ("argmax", "com", "gaussian"):
        p = detect_peaks(on, off, method=method)
        col = p.columns()
        assert np.all(np.isnan(col[81:140])) and np.all(p.status[81:140] == STATUS_WEAK)
        assert np.isfinite(col).sum() == H - 59 and p.rejected["weak"] == 59
    r = detect_peaks(on, off, method="ridge")
    assert not np.any((r.points[:, 1] > 84) & (r.points[:, 1] < 136))
    black = np.zeros((H, W), np.uint8)
    for method in ("gaussian", "com", "ridge", "argmax"):
        p = detect_peaks(black, black, method=method)
        assert len(p) == 0 and p.points.shape == (0, 2)
        with pytest.raises(DecodeError, match="laser frame scan/0007/laser0.png: found 0 line peaks.*no laser line"):
            require_peaks(p, "scan/0007/laser0.png")
    dark_on, dark_off = row_line(CENTRES, 4.0, 0.0, W=W, noise=2.0, seed=9)   # noise only, laser off
    assert len(detect_peaks(dark_on, dark_off)) == 0
    assert require_peaks(detect_peaks(on, off), "ok.png", min_points=100).method == "gaussian"


@pytest.mark.parametrize("method", ["gaussian", "com"])
def test_confidence_ranks_the_errors(method):
    rng = np.random.default_rng(11)
    heights = rng.uniform(12.0, 250.0, H * 2)          # a different brightness in every row
    centres = 95.0 + 30.0 * np.sin(np.arange(2 * H) / 60.0)
    on, off = row_line(centres, 5.0, heights, W=W, noise=2.0, seed=12)
    p = detect_peaks(on, off, method=method, min_contrast=3.0)
    assert len(p) >= 0.95 * 2 * H
    _assert_confidence_ranks(np.abs(p.points[:, 0] - centres[p.rows]), p.confidence)


def test_ridge_confidence_ranks_the_errors():
    # the brightness falls along the line from 250 to 8 DN (a row-random brightness is no 2D line: the
    # ridge's smoothing across rows mixes them)
    a = np.radians(15.0)
    dist = slanted(15.0, 100.3, 300.0)

    def height(u, v):
        return 8.0 + 242.0 * np.clip(((u - 100.3) * np.sin(a) + v * np.cos(a)) / 600, 0, 1) ** 2

    on, off = curve_line(dist, 600, 260, 5.0, height, noise=2.0, seed=3, ss=4)
    p = detect_peaks(on, off, method="ridge", min_contrast=3.0)   # down to the faint end, like the row test
    assert len(p) >= 500
    _assert_confidence_ranks(np.abs(dist(p.points[:, 0], p.points[:, 1])), p.confidence)


def _assert_confidence_ranks(err, confidence):
    low = confidence <= np.quantile(confidence, 0.1)
    assert err[low].mean() >= 3.0 * err[~low].mean(), (err[low].mean(), err[~low].mean())
    big = err >= np.quantile(err, 0.9)
    assert (big & low).sum() >= 0.4 * big.sum()        # the worst decile by confidence holds the large errors
    # the confidence is the inverse of the predicted std: it predicts the error's size
    assert 0.6 < np.sqrt(np.mean((err * confidence) ** 2)) < 1.6


def test_rgb_channels_and_the_noise_estimate():
    on, off = row_line(CENTRES, 4.0, 180.0, W=W, noise=1.5, seed=13)
    rng = np.random.default_rng(14)
    ambient = rng.integers(0, 60, (H, W), dtype=np.uint8)
    on_rgb = np.stack([on, ambient, ambient], axis=-1)      # a red laser; green and blue see only ambient
    off_rgb = np.stack([off, ambient, ambient], axis=-1)
    red = detect_peaks(on_rgb, off_rgb, channel="red")
    assert np.sqrt(np.mean((red.columns() - CENTRES) ** 2)) <= 0.05
    grey = detect_peaks(on_rgb, off_rgb)                     # the mean of the channels: a third of the height
    assert np.median(grey.height) == pytest.approx(np.median(red.height) / 3, rel=0.1)
    assert len(detect_peaks(on_rgb, off_rgb, channel="green")) == 0
    d, _ = laser_difference(on, off)
    assert estimate_noise(d) == pytest.approx(1.5 * np.sqrt(2.0), rel=0.1)   # the difference of two frames
    assert red.noise == pytest.approx(1.5 * np.sqrt(2.0), rel=0.1)
    # without a laser-off frame the ambient stays in the difference: a dark background still works
    assert np.sqrt(np.mean((detect_peaks(on).columns() - CENTRES) ** 2)) <= 0.05


@pytest.mark.parametrize("kwargs, mention", [
    (dict(on=np.zeros((4, 5, 2))), "laser-on image must be (H, W) grey or (H, W, 3) RGB"),
    (dict(on=np.zeros((4, 5)), off=np.zeros((4, 6))), "laser-off image must have the laser-on image's shape"),
    (dict(on=np.zeros((4, 5)), method="steger"), "method must be one of gaussian, com, ridge, argmax"),
    (dict(on=np.zeros((4, 5)), channel="infrared"), "channel must be None, 'white'"),
    (dict(on=np.zeros((4, 5)), window=2), "window must be a whole number of pixels >= 3"),
    (dict(on=np.zeros((4, 5)), min_contrast=0), "min_contrast must be a finite number > 0"),
    (dict(on=np.zeros((4, 5)), double_ratio=1.5), "double_ratio must be in (0, 1]"),
    (dict(on=np.zeros((4, 5), bool)), "integer or float dtype"),
    (dict(on=np.zeros((9, 9)), method="ridge", sigma=0.1), "sigma must be >= 0.5"),
    (dict(on=np.full((9, 9), np.nan)), "NaN or infinite values"),
])
def test_bad_input_is_named(kwargs, mention):
    """Each bad argument raises InputError naming the argument, the expected and the found value."""
    on = kwargs.pop("on")
    with pytest.raises(InputError) as info:
        detect_peaks(on, **kwargs)
    assert mention in str(info.value)
