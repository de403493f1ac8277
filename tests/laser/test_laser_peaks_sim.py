"""Peak detection on the simulator's own laser frames: the default laser
rig, RGB 8-bit camera, line width 0.8 mm, default noise and speckle, against the exact image projection of
the lit curve (:func:`rangekit.sim.laser.truth.column_errors`). benchmarks/laser/bench_laser_peaks_sim.py
measures the same over more objects and angles (docs/laser.md)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from support.laser_lines import row_line
from rangekit.errors import InputError
from rangekit.laser import detect_peaks
from rangekit.sim import ImagingModel, default_scene
from rangekit.sim.laser.frames import LaserLook, LaserView
from rangekit.sim.laser.rig import laser_rig
from rangekit.sim.laser.truth import column_errors, curve_distance

CASES = (("lumpy", 0.0), ("lumpy", 100.0), ("sphere", 40.0), ("sphere", 200.0))


def _frames(imaging, look):
    rig = laser_rig()
    out = []
    for obj, angle in CASES:
        view = LaserView(default_scene(obj), rig, np.radians(angle), imaging=imaging, look=look, seed=int(angle),
                         ambient_scale=4)
        off = view.off()
        out += [(view.frame(k).image, off, view.curve(k).uv) for k in range(len(rig.lasers))]
    return out


@pytest.fixture(scope="module")
def frames():
    return _frames(ImagingModel(colour=True), LaserLook())


def _measure(frames, method, **options):
    errs, conf, dist = [], [], []
    for on, off, uv in frames:
        p = detect_peaks(on, off, method=method, channel="red", **options)
        e = column_errors(p.points, uv)
        ok = np.isfinite(e)
        assert ok.mean() > 0.95 if method != "ridge" else ok.mean() > 0.9   # nearly every peak is compared
        errs.append(e[ok])
        conf.append(p.confidence[ok])
        dist.append(curve_distance(p.points, uv))
    return np.concatenate(errs), np.concatenate(conf), np.concatenate(dist)


@pytest.mark.parametrize("method, options, limit", [("ridge", {}, 0.05), ("gaussian", {}, 0.08),
                                                     ("gaussian", {"along": 3}, 0.05)])
def test_peak_error_on_simulated_frames(frames, method, options, limit):
    # measured 0.044 px (ridge), 0.069 px (Gaussian), 0.043 (Gaussian smoothed along 7 rows) over these
    # 8 frames: 0.1 px off would be > 0.1
    e, _, dist = _measure(frames, method, **options)
    assert len(e) > 3000
    rms = np.sqrt(np.mean(e ** 2))
    assert rms <= limit, rms
    assert abs(e.mean()) < 0.01                             # unbiased
    assert (dist < 1.0).mean() > 0.99                       # no spurious points off the line


@pytest.mark.parametrize("method, options", [("gaussian", {}), ("ridge", {}), ("gaussian", {"along": 3})])
def test_confidence_ranks_the_errors_on_simulated_frames(frames, method, options):
    e, conf, _ = _measure(frames, method, **options)
    err = np.abs(e)
    low = conf <= np.quantile(conf, 0.1)
    large = err > 3.0 * np.sqrt(np.mean(e ** 2))
    assert large.sum() >= 20
    assert (large & low).sum() >= 0.6 * large.sum()         # the worst decile holds most of the large errors
    assert err[low].mean() >= 2.0 * err[~low].mean()


def test_noiseless_frames_leave_only_the_rendering_floor():
    # no shot/read noise, no speckle: 8-bit quantisation and the line's own shape (curvature, brightness
    # changing along it) are what is left; 0.022 px measured (0.029 with point-sampled lines)
    imaging = replace(ImagingModel(colour=True), full_well=0.0, read_noise=0.0)
    e, _, _ = _measure(_frames(imaging, LaserLook(speckle=0.0))[::2], "gaussian")
    assert np.sqrt(np.mean(e ** 2)) <= 0.03


def test_column_errors_of_an_exact_curve():
    # a straight slanted curve sampled 0.5 px apart: points on it have error 0, a shift is measured exactly,
    # rows near its ends and beyond it are NaN
    v = np.arange(0.0, 100.0, 0.4)
    uv = np.column_stack([50.0 + 0.7 * v, v])
    rows = np.arange(5.0, 95.0)
    on = np.column_stack([50.0 + 0.7 * rows, rows])
    np.testing.assert_allclose(column_errors(on, uv), 0.0, atol=1e-12)
    np.testing.assert_allclose(column_errors(on + [0.1, 0.0], uv), 0.1, atol=1e-12)
    ends = np.array([[50.0, 0.0], [50.7, 1.0], [50.0 + 0.7 * 99, 99.0], [120.0, 120.0]])
    assert np.isnan(column_errors(ends, uv)).all()
    flat = np.column_stack([np.arange(0.0, 100.0, 0.4), np.full(250, 30.0)])   # along a row: no one column
    assert np.isnan(column_errors([[50.0, 30.0]], flat)).all()


def test_smoothing_along_the_line_keeps_steps_and_ends():
    # a smooth curve with a 3 px step at row 150 (a depth edge): smoothing lowers the noise-driven error
    # and leaves the rows at the step and the ends alone
    rows = np.arange(300)
    centres = 100.0 + 20.0 * np.sin(rows / 40.0) + np.where(rows >= 150, 3.0, 0.0)
    on, off = row_line(centres, 4.0, 60.0, W=200, noise=2.0, seed=5)
    raw = detect_peaks(on, off)
    smooth = detect_peaks(on, off, along=3)
    e_raw, e_smooth = raw.points[:, 0] - centres[raw.rows], smooth.points[:, 0] - centres[smooth.rows]
    inner = (np.abs(raw.rows - 150) > 4) & (raw.rows > 3) & (raw.rows < 296)
    assert np.sqrt(np.mean(e_smooth[inner] ** 2)) < 0.75 * np.sqrt(np.mean(e_raw[inner] ** 2))
    near_step = np.abs(raw.rows - 149.5) < 2
    assert np.abs(e_smooth[near_step]).max() < 0.3                   # not smeared across the step
    np.testing.assert_array_equal(smooth.points[:3], raw.points[:3])  # no rows either side: unchanged
    with pytest.raises(InputError, match="along must be a whole number of rows in 0..10, found 11"):
        detect_peaks(on, off, along=11)
