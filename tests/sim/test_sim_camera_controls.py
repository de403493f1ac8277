"""The simulated camera's controls: exposure and ISO as a real sensor, auto-exposure with a lag,
the projector's latency on the devices' shared virtual clock, and the refusal of auto-exposure for coded light."""

import sys
from dataclasses import replace

import cv2
import numpy as np
import pytest

from support.small_rigs import small_projector_rig

from rangekit.app.acquire.acquire import acquire
from rangekit.coded.reconstruct import reconstruct_view
from rangekit.rig.camera_controls import CameraControls
from rangekit.cli import main
from rangekit.coded.patterns import make_pattern_spec
from rangekit.errors import ConfigError
from rangekit.formats.sessions.session import CaptureSettings, ScanPlan
from rangekit.sim import ImagingModel, SimRig, default_rig, default_scene
from rangekit.sim.devices import sim_rig as sim_devices
from rangekit.sim.imaging.sensor import AE_TARGET, REF_EXPOSURE_US, Exposure, noise_std

AUTO = CameraControls(exposure_us=None, allow_auto_exposure=True)


def small_rig():
    return small_projector_rig()


@pytest.fixture(scope="module")
def scene():
    return default_scene("lumpy")


def flat(value, sim):
    W, H = sim.projector.resolution
    return np.full((H, W), value, np.uint8)


def shoot(sim, pattern, controls=None):
    if controls is not None:
        sim.camera.set_controls(controls)
    sim.projector.show(pattern)
    return sim.camera.capture()


def test_default_controls_keep_the_images(scene):
    a, b = SimRig(scene, small_rig(), seed=4), SimRig(scene, small_rig(), seed=4)
    b.camera.set_controls(CameraControls())
    for v in (255, 128, 0):
        assert np.array_equal(shoot(a, flat(v, a)), shoot(b, flat(v, b)))


def test_exposure_doubles_the_signal_below_saturation(scene):
    sim = SimRig(scene, small_rig(), imaging=ImagingModel().noiseless())
    one = shoot(sim, flat(150, sim), CameraControls(exposure_us=10000.0)).astype(int)
    two = shoot(sim, flat(150, sim), CameraControls(exposure_us=20000.0)).astype(int)
    below = (one > 5) & (two < 250)
    assert below.sum() > 5000
    assert np.abs(two[below] - 2 * one[below]).max() <= 1     # rounding of each image only


def test_noise_is_shot_plus_read_at_the_exposure(scene):
    """Two captures of one state differ by their noise only: the variance of the difference is twice the
    predicted shot + read variance at that exposure (16 bits: quantisation negligible)."""
    model = ImagingModel(bits=16)
    sim = SimRig(scene, small_rig(), imaging=model, seed=2)
    pattern = flat(200, sim)
    exposure = Exposure(2.0 * REF_EXPOSURE_US, 100)
    controls = CameraControls(exposure_us=exposure.exposure_us)
    a = shoot(sim, pattern, controls).astype(np.float64) / model.max_value
    b = shoot(sim, pattern, controls).astype(np.float64) / model.max_value
    signal = sim.renderer().expected(pattern)
    band = (signal > 0.1) & (signal < 0.3)            # 0.2 .. 0.6 of full scale at twice the exposure
    assert band.sum() > 3000
    measured = np.var((a - b)[band]) / 2
    predicted = np.mean(noise_std(model, signal[band], exposure) ** 2)
    assert measured == pytest.approx(predicted, rel=0.06)
    # shot noise at the reference exposure would be about half of it: the test would see it
    assert np.mean(noise_std(model, signal[band], Exposure()) ** 2) < 0.6 * predicted


def test_saturation_rises_with_exposure(scene):
    sim = SimRig(scene, small_rig())
    hit = sim.ground_truth().hit
    fractions = [float((shoot(sim, flat(255, sim), CameraControls(exposure_us=e))[hit] == 255).mean())
                 for e in (10000.0, 33333.0, 100000.0, 300000.0)]
    assert fractions[0] == 0 and all(b > a for a, b in zip(fractions[1:], fractions[2:]))
    assert fractions[-1] > 0.5


def test_iso_gain_amplifies_read_noise_and_exposure_does_not(scene):
    """Pixels that see nothing (no surface within the lens blur): only read noise, clipped at 0 (std
    proportional to sigma)."""
    model = ImagingModel(bits=16)
    sim = SimRig(scene, small_rig(), imaging=model, seed=5)
    dark = cv2.erode((~sim.ground_truth().hit).astype(np.uint8), np.ones((9, 9), np.uint8)).astype(bool)
    assert dark.sum() > 10000
    black = flat(0, sim)
    std = {name: float(shoot(sim, black, c)[dark].std())
           for name, c in {"ref": CameraControls(), "iso800": CameraControls(iso=800),
                           "long": CameraControls(exposure_us=8 * REF_EXPOSURE_US)}.items()}
    assert std["iso800"] / std["ref"] == pytest.approx(8.0, rel=0.03)
    assert std["long"] / std["ref"] == pytest.approx(1.0, rel=0.03)


def test_auto_exposure_follows_the_mean_with_a_lag_and_is_deterministic(scene):
    def means():
        sim = SimRig(scene, small_rig(), seed=1)
        sim.camera.set_controls(AUTO)
        out = [shoot(sim, flat(255, sim)) for _ in range(12)]
        return [float(i.mean()) / 255 for i in out], out

    m, images = means()
    assert m[0] < 0.6 * AE_TARGET                                 # the default exposure is darker than the target
    assert m[0] < m[1] < m[3] < AE_TARGET                         # it moves a part of the way each frame
    assert m[-1] == pytest.approx(AE_TARGET, rel=0.03)            # and settles on the target
    assert all(np.array_equal(a, b) for a, b in zip(images, means()[1]))


def test_auto_exposure_ruins_a_graycode_decode(scene):
    """Acceptance: with auto-exposure on, a Gray-code view decodes less than 80% of the pixels
    it decodes with the exposure locked (full rig: 260311 of 401484, 65%; this 320x256 rig: about 30%)."""
    spec = make_pattern_spec("graycode", (320, 200))

    def decoded(controls):
        sim = SimRig(scene, small_rig())
        sim.camera.set_controls(controls)
        images = sim.capture_sequence(list(spec.frames()))
        return int(reconstruct_view(images, spec, sim.rig.camera, sim.rig.projector).triangulated.valid.sum())

    locked, auto = decoded(CameraControls()), decoded(AUTO)
    assert locked > 0.6 * SimRig(scene, small_rig()).ground_truth().lit.sum()
    assert auto < 0.8 * locked


def test_projector_latency_shows_the_previous_patterns_until_the_delay_covers_it(scene):
    """Latency 50 ms at 30 fps (frames start on ticks 33.3 ms apart): without a wait, frame k sees pattern
    k - 2 (shown 1 and 2 frames earlier, neither 50 ms old yet); a 20 ms wait, pattern k - 1; a wait of
    the latency or more, pattern k."""
    values = [255, 0, 255, 255, 0, 0, 255, 0]

    def lit(delay):
        sim = SimRig(scene, small_rig(), latency_s=0.05)
        hit = sim.ground_truth().lit
        out = []
        for v in values:
            sim.projector.show(flat(v, sim))
            shown = sim.clock.now()
            sim.sleep(delay)
            out.append(float(sim.camera.capture()[hit].mean()) > 40)
            assert sim.camera.last_frame_time >= shown + delay - 1e-9
        return out

    want = [v == 255 for v in values]
    assert lit(0.0) == [False, False, *want[:-2]]
    assert lit(0.02) == [False, *want[:-1]]
    assert lit(0.05) == want and lit(0.1) == want


def test_acquire_waits_on_the_devices_clock(scene, tmp_path):
    """A scan with pattern_delay_s >= the latency records the bytes a rig without latency records, in
    virtual time (the clock moved by at least the delays)."""
    spec = make_pattern_spec("graycode", (320, 200))
    rig = small_rig()
    plain, late = SimRig(scene, rig), SimRig(scene, rig, latency_s=0.05)
    acquire(plain, rig, spec, tmp_path / "a", plan=ScanPlan(n_views=1))
    acquire(late, rig, spec, tmp_path / "b", plan=ScanPlan(n_views=1), capture=CaptureSettings(bits=8, pattern_delay_s=0.05))
    for f in sorted((tmp_path / "a" / "view_000").glob("*.png")):
        assert f.read_bytes() == (tmp_path / "b" / "view_000" / f.name).read_bytes(), f.name
    assert late.clock.now() >= spec.n_frames * 0.05


def auto_rig():
    r = default_rig()
    return replace(r, cameras=(r.camera.resized(320, 256),),
                   capture={**r.capture, "camera": {"exposure_us": "auto"}})


def test_acquire_refuses_auto_exposure_for_coded_light(scene, tmp_path):
    spec = make_pattern_spec("graycode", (1280, 800))
    with pytest.raises(ConfigError, match=r"capture\.camera\.exposure_us: coded light needs a locked exposure"):
        acquire(SimRig(scene, auto_rig()), auto_rig(), spec, tmp_path / "s")
    assert not (tmp_path / "s").exists()                   # refused before anything was made


def test_cli_refuses_auto_exposure_unless_asked(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(sim_devices, "default_rig", auto_rig)
    args = ["scan", "--out", str(tmp_path / "s"), "--views", "2", "--patterns", "graycode", "--no-process"]
    assert main(args) == 1
    err = capsys.readouterr().err
    assert "capture.camera.exposure_us" in err and "auto" in err
    assert not (tmp_path / "s" / "session.json").exists()

    seen = {}

    def stop(devices, *a, **k):      # acquisition proper: record the camera's controls, then stop
        seen["controls"] = devices.camera.controls
        raise KeyboardInterrupt

    monkeypatch.setattr(sys.modules["rangekit.app.acquire.acquire"], "_acquire", stop)
    assert main([*args, "--allow-auto-exposure"]) == 130
    assert seen["controls"].auto_exposure and seen["controls"].allow_auto_exposure
