"""Time of flight against the simulator's exact truth: N-bucket, unwrapping, noise, geometry, pulsed."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from rangekit.errors import InputError
from rangekit.sim.sensors.tof import (KINECT_V2_PLAN, LUXONIS_PLAN, ToFSensor, render_pulsed, render_tof, tof_camera,
                              tof_scene)
from rangekit.tof import (C_LIGHT, FrequencyPlan, decode_cw, phase_amplitude_offset, phase_to_range, pulsed_range,
                          range_to_depth, range_to_points, unwrap_ranges)


def _decode(cap, **kw):
    s = cap.sensor
    return decode_cw(cap.samples, cap.plan, cap.camera, electrons_per_unit=s.electrons_per_dn,
                     read_noise_e=s.read_noise_e, saturation=(1 << s.bits) - 1, **kw)


def _correct(cap, res) -> np.ndarray:
    """Right wrap count <=> the range is within half the finest wrap length of the truth."""
    return np.abs(res.unwrap.range - cap.range_true) < 0.5 * cap.plan.wrap_lengths.min()


def _snr(cap) -> np.ndarray:
    """(F, H, W) amplitude over per-sample noise (electrons), from the simulator's noise-free signal."""
    return cap.amplitude_true / np.sqrt(cap.offset_true + cap.sensor.read_noise_e ** 2)


@pytest.fixture(scope="module")
def kinect():
    """16/80/120 MHz x 3 steps on panels from 0.5 to 15 m, default (realistic) sensor."""
    cap = render_tof(tof_scene(0.5, 15.0), KINECT_V2_PLAN, seed=1)
    return cap, _decode(cap)


def test_plan_unambiguous_ranges():
    assert KINECT_V2_PLAN.unambiguous_range == pytest.approx(C_LIGHT / (2 * 8e6), rel=1e-12)  # 18.74 m
    assert LUXONIS_PLAN.unambiguous_range == pytest.approx(C_LIGHT / (2 * 20e6), rel=1e-12)    # 7.49 m
    assert FrequencyPlan.uniform([80e6], 4).unambiguous_range == pytest.approx(C_LIGHT / 160e6)
    assert KINECT_V2_PLAN.n_samples == 9 and LUXONIS_PLAN.n_samples == 8


@pytest.mark.parametrize("steps", [(0, 2 * np.pi / 3, 4 * np.pi / 3), (0, np.pi / 2, np.pi, 3 * np.pi / 2),
                                   (0.1, 0.9, 2.0, 4.0, 5.5)])
def test_n_bucket_recovers_phase_amplitude_offset_exactly(steps):
    rng = np.random.default_rng(0)
    phi = rng.uniform(0, 2 * np.pi, (7, 9))
    A, B = rng.uniform(1, 50, (7, 9)), rng.uniform(60, 100, (7, 9))
    plan = FrequencyPlan((20e6,), (steps,))
    S = np.stack([B + A * np.cos(phi - t) for t in steps])
    m = phase_amplitude_offset(S, plan)
    assert np.abs(np.angle(np.exp(1j * (m.phase[0] - phi)))).max() < 1e-12
    assert np.abs(m.amplitude[0] - A).max() < 1e-11 and np.abs(m.offset[0] - B).max() < 1e-11


def test_kinect_plan_unwraps_0p5_to_15m(kinect):
    cap, res = kinect
    good = cap.hit & ~cap.mixed
    r = cap.range_true
    assert r[good].min() < 0.55 and r[good].max() > 14.9
    # The signal-to-noise ratio the acceptance is stated at: A / sigma per sample at the far panels.
    snr_far = np.median(_snr(cap)[0][good & (r > 12)])
    snr_near = np.median(_snr(cap)[0][good & (r < 0.6)])
    assert 5 < snr_far < 10, snr_far  # measured 7.3 (phase noise 0.11 rad at 3 steps)
    correct = _correct(cap, res)
    print(f"16/80/120 MHz: {correct[good].mean():.4%} of {good.sum()} unmixed pixels right; A/sigma per sample "
          f"{snr_far:.1f} beyond 12 m, {snr_near:.0f} below 0.6 m; brightest sample {cap.expected.max():.3g} e- "
          f"(full well {cap.sensor.full_well_e:.3g})")
    assert correct[good].mean() >= 0.999  # measured 1.0 over 74.8k pixels
    # Every wrap count occurs, so the test would catch a wrong unwrapping: one frequency alone fails.
    U = cap.plan.wrap_lengths
    assert len(np.unique(np.floor(r[good] / U[2]))) == 13
    single = phase_to_range(res.phase[2], cap.plan.frequencies[2])
    beyond = good & (r > U[2])
    assert (np.abs(single - r)[beyond] < 0.1).mean() < 0.1


def test_combined_range_noise_matches_theory(kinect):
    """sigma_r = c sigma_phi / (4 pi f) per frequency, combined by inverse variance; measured against
    the decode of the exact noise-free samples, with the exact first-order phase variance per sample."""
    cap, res = kinect
    clean = decode_cw(cap.expected, cap.plan, cap.camera, read_noise_e=cap.sensor.read_noise_e)
    sig = cap.noise_sigma_e()
    inv_var = 0.0
    for j, (sl, steps) in enumerate(zip(cap.plan.slices(), cap.plan.steps)):
        A, phi, n = cap.amplitude_true[j], clean.phase[j], len(steps)
        var_phi = 4 / (n * n * A * A) * sum(sig[sl][k] ** 2 * np.sin(phi - t) ** 2 for k, t in enumerate(steps))
        inv_var = inv_var + 1 / ((C_LIGHT / (4 * np.pi * cap.plan.frequencies[j])) ** 2 * var_phi)
    sigma_theory = 1 / np.sqrt(inv_var)
    m = res.valid & clean.valid & ~cap.mixed
    z = (res.range - clean.range)[m] / sigma_theory[m]
    bias = np.abs(clean.range - cap.range_true)[m]
    print(f"noise / theory {z.std():.3f}, mean {z.mean():.4f}; predicted sigma / theory "
          f"{np.median(res.sigma_range[m] / sigma_theory[m]):.3f}; noise-free error median {np.median(bias) * 1e6:.1f} um, "
          f"max {bias.max() * 1e6:.1f} um")
    assert 0.9 <= z.std() <= 1.1, z.std()          # measured 1.02
    assert abs(z.mean()) < 0.02
    # The decoder's own prediction (from measured amplitude and offset) agrees too.
    ratio = np.median(res.sigma_range[m] / sigma_theory[m])
    assert 0.9 <= ratio <= 1.1, ratio
    # And the noise-free decode is exact up to the pixel's own averaging (sub-micrometre on panels).
    assert np.abs(clean.range - cap.range_true)[m].max() < 2e-5


def test_radial_distance_to_depth_and_points_exact(kinect):
    cap, _ = kinect
    cam = cap.camera
    assert np.abs(cam.dist).max() > 0.05  # a distorted lens: z != r along off-axis rays
    depth = range_to_depth(cap.range_true, cam)
    print(f"range to depth: max error {np.nanmax(np.abs(depth - cap.depth_true)):.2g} m")
    assert np.nanmax(np.abs(depth - cap.depth_true)) < 1e-9
    assert np.nanmax(np.abs(range_to_points(cap.range_true, cam) - cap.xyz_true)) < 1e-9
    assert np.nanmax(np.abs(depth - cap.range_true)) > 1.0  # the conversion matters


def test_two_frequencies_80_100_mhz_beyond_1p875m():
    cap = render_tof(tof_scene(0.5, 7.3), LUXONIS_PLAN, camera=tof_camera(160, 120), seed=2)
    res = _decode(cap)
    r = cap.range_true
    beyond = cap.hit & ~cap.mixed & (r > 1.875)
    print(f"80/100 MHz: {_correct(cap, res)[beyond].mean():.4%} of {beyond.sum()} pixels from 1.875 to "
          f"{r[beyond].max():.2f} m right")
    assert r[beyond].max() > 7.2 and beyond.sum() > 5000
    assert _correct(cap, res)[beyond].mean() >= 0.999  # measured 1.0
    assert res.valid[beyond].mean() > 0.99
    single = phase_to_range(res.phase[0], 80e6)  # one frequency folds everything beyond 1.875 m
    assert (np.abs(single - r)[beyond] < 0.1).mean() < 0.05


def test_flying_pixels_are_removed(kinect):
    cap, res = kinect
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN rows: pixels with no range
        err_any = np.nanmin(np.abs(cap.subray_range - res.unwrap.range[..., None]), axis=2)
    flying = cap.mixed & (err_any > 0.02)  # more than 2 cm from every surface the pixel sees
    good = cap.hit & ~cap.mixed
    print(f"flying pixels removed {(~res.valid[flying]).mean():.1%} of {flying.sum()}, unmixed removed "
          f"{(~res.valid[good]).mean():.3%}")
    assert flying.sum() > 500
    assert (~res.valid[flying]).mean() >= 0.85   # measured 0.89
    assert (~res.valid[good]).mean() <= 0.002    # measured 0.0006
    unfiltered = _decode(cap, flying_angle=None)
    assert (~unfiltered.valid[flying]).mean() < 0.4  # without the filter most would stay


def test_ambiguity_flag_catches_wrong_wraps_at_low_snr():
    cap = render_tof(tof_scene(0.5, 15.0), KINECT_V2_PLAN, camera=tof_camera(160, 120),
                     sensor=ToFSensor(signal_e=1e4), seed=3)
    res = _decode(cap, min_snr=0.0, flying_angle=None)
    good = cap.hit & ~cap.mixed
    correct = _correct(cap, res)
    print(f"signal_e 1e4: A/sigma {np.median(_snr(cap)[0][good & (cap.range_true > 12)]):.1f} beyond 12 m; "
          f"{correct[good].mean():.2%} right, {correct[good & ~res.ambiguous].mean():.3%} of the unflagged")
    assert correct[good].mean() < 0.99                      # the far panels are too dark (measured 0.978)
    assert correct[good & ~res.ambiguous].mean() >= 0.998   # what is not flagged is right (measured 0.999)


def test_multipath_biases_range_and_shows_in_the_residual():
    cam = tof_camera(160, 120)
    plain = render_tof(tof_scene(), camera=cam, seed=4)
    multi = render_tof(tof_scene(), camera=cam, sensor=ToFSensor(multipath_strength=0.2, multipath_extra_m=1.0),
                       seed=4)
    rp, rm = _decode(plain), _decode(multi)
    good = plain.hit & ~plain.mixed
    assert abs(np.nanmedian((rp.unwrap.range - plain.range_true)[good])) < 1e-3
    print(f"multipath: bias {np.nanmedian((rm.unwrap.range - multi.range_true)[good]) * 1e3:.1f} mm, median residual "
          f"{np.nanmedian(rm.unwrap.residual[good]):.1f} vs {np.nanmedian(rp.unwrap.residual[good]):.2f}")
    assert np.nanmedian((rm.unwrap.range - multi.range_true)[good]) > 0.02      # measured 4 cm
    assert np.nanmedian(rm.unwrap.residual[good]) > 10 * np.nanmedian(rp.unwrap.residual[good])


def test_pulsed_range_noise_is_timing_jitter():
    cap = render_pulsed(tof_scene(), camera=tof_camera(160, 120), jitter_s=50e-12, seed=5)
    err = (pulsed_range(cap.round_trip_s) - cap.range_true)[cap.hit]
    sigma = C_LIGHT * 50e-12 / 2  # 7.5 mm
    print(f"pulsed: std {err.std() * 1e3:.2f} mm vs {sigma * 1e3:.2f} mm")
    assert err.std() == pytest.approx(sigma, rel=0.1)
    assert abs(err.mean()) < 4 * sigma / np.sqrt(err.size)
    exact = render_pulsed(tof_scene(), camera=tof_camera(160, 120), jitter_s=0.0)
    assert np.nanmax(np.abs(pulsed_range(exact.round_trip_s) - exact.range_true)) < 1e-12


def test_bad_input_names_expected_and_found():
    cam = tof_camera(16, 12)
    with pytest.raises(InputError, match=r"16/80/120 MHz x 3/3/3 steps\) needs 9 raw samples, found 8"):
        decode_cw(np.zeros((8, 12, 16)), KINECT_V2_PLAN, cam)
    with pytest.raises(InputError, match="samples are 20x12 but camera 'tof' is 16x12"):
        decode_cw(np.zeros((9, 12, 20)), KINECT_V2_PLAN, cam)
    with pytest.raises(InputError, match="at least 3 distinct phase steps"):
        FrequencyPlan((80e6,), ((0.0, np.pi),))
    with pytest.raises(InputError, match="max_range must be in"):
        unwrap_ranges(np.zeros((2, 3, 3)), LUXONIS_PLAN, max_range=10.0)
    with pytest.raises(InputError, match="range map is"):
        range_to_depth(np.zeros((5, 5)), cam)


def test_cli_sim_render_then_tof(tmp_path, capsys):
    from rangekit.cli import main

    raw, out = tmp_path / "raw", tmp_path / "out"
    assert main(["sim", "render", "--sensor", "tof", "--size", "160x120", "--out", str(raw)]) == 0
    assert main(["tof", str(raw), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "wrong wrap (> 0.3 m) 0.000%" in printed
    truth = np.load(raw / "ground_truth.npz")
    depth, rng = np.load(out / "depth.npy"), np.load(out / "range.npy")
    ok = np.isfinite(depth) & truth["valid"]
    assert ok.mean() > 0.9
    assert np.abs(depth - truth["depth"])[ok].max() < 0.1              # no wrong wrap anywhere
    assert np.sqrt(np.mean((rng - truth["range"])[ok] ** 2)) < 0.01     # measured 6 mm (far panels dominate)
    conf = np.load(out / "confidence.npy")
    assert conf.dtype == np.float32 and np.all(conf[~np.isfinite(depth)] == 0) and conf[ok].min() > 0
    from rangekit.formats.clouds import load_cloud
    assert len(load_cloud(out / "cloud.ply")) == int(np.isfinite(depth).sum())
    for name in ("depth.png", "confidence.png"):
        assert (out / name).stat().st_size > 0

    # A missing sample: the plan in tof.json does not match what is on disk.
    (raw / "samples" / "008.png").unlink()
    assert main(["tof", str(raw), "--out", str(tmp_path / "out2")]) == 1
    err = capsys.readouterr().err
    assert "samples: the frequency plan in tof.json (16/80/120 MHz x 3/3/3 steps) needs 9 raw samples, found 8" in err


def test_cli_pulsed(tmp_path, capsys):
    from rangekit.cli import main

    raw, out = tmp_path / "raw", tmp_path / "out"
    assert main(["sim", "render", "--sensor", "tof-pulsed", "--size", "80x60", "--jitter-ps", "10",
                 "--out", str(raw)]) == 0
    assert main(["tof", str(raw), "--out", str(out)]) == 0
    truth = np.load(raw / "ground_truth.npz")
    err = np.load(out / "range.npy") - truth["range"]
    assert np.nanstd(err) == pytest.approx(C_LIGHT * 10e-12 / 2, rel=0.15)
    assert main(["sim", "render", "--sensor", "tof", "--object", "sphere", "--out", str(tmp_path / "x")]) == 2
    assert "--object: only for --sensor projector" in capsys.readouterr().err
