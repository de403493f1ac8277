"""Projector response (gamma): fit from grey levels, phase correction, rig file.

Against the simulator's truth: ImagingModel's projector response ``black + (1 - black) p ** gamma``,
default noise, 8 bits. Run with ``pytest -s`` to see the measured figures quoted in docs/coded-light.md.
"""

import json

import numpy as np
import pytest
from scipy.ndimage import binary_erosion

from rangekit.calib.response import measure_response
from rangekit.coded.decode import decode
from rangekit.coded.phase import phase_from_steps
from rangekit.errors import ConfigError, DecodeError, InputError
from rangekit.coded.patterns import make_pattern_spec
from rangekit.coded.response import fit_response, phase_correction
from rangekit.rig.projector_response import ProjectorResponse
from rangekit.rig.rig_file import Rig, load_rig, save_rig, template_rig
from rangekit.sim import ImagingModel, SimRig, default_rig, default_scene


# --------------------------------------------------------------------------- fit
@pytest.mark.parametrize("gamma", [2.2, 1.0])
def test_gamma_fitted_from_simulated_grey_levels(gamma):
    sim = SimRig(default_scene("sphere"), imaging=ImagingModel(gamma=gamma), seed=0)
    calls = []
    fit = measure_response(sim.projector, sim.camera, progress=lambda msg, done=None, total=None: calls.append(done))
    print(f"\ngamma {gamma}: {fit!r}, error {fit.response.gamma / gamma - 1:+.3%}")
    assert abs(fit.response.gamma / gamma - 1) < 0.003  # measured: under 0.05%
    assert fit.rms < 0.002 and fit.n_pixels > 50_000
    assert len(fit.levels) == 17 and fit.levels[0] == 0 and fit.levels[-1] == 1 and calls[-1] == 17
    np.testing.assert_allclose(fit.measured, fit.levels ** gamma, atol=0.005)


def test_fit_is_independent_of_albedo_ambient_and_black_level():
    rng = np.random.default_rng(1)
    levels = np.linspace(0, 1, 9)
    a = rng.uniform(10, 40, (60, 80))          # ambient + black leak, DN
    b = rng.uniform(80, 200, (60, 80))         # albedo x shading x exposure, DN
    images = [np.clip(np.rint(a + b * p ** 1.9 + rng.normal(0, 0.7, a.shape)), 0, 255).astype(np.uint8)
              for p in levels]
    fit = fit_response(levels[::-1], images[::-1])  # any order
    assert abs(fit.response.gamma - 1.9) < 0.01 and fit.n_pixels > 3000
    left = np.broadcast_to(np.arange(80) < 40, (60, 80))
    masked = fit_response(levels, images, mask=left)
    assert masked.n_pixels == left.sum() and abs(masked.response.gamma - 1.9) < 0.01
    with pytest.raises(InputError, match="mask has shape"):
        fit_response(levels, images, mask=left.T)


def test_fit_input_errors_name_the_fix():
    img = np.full((40, 40), 100, np.uint8)
    with pytest.raises(InputError, match="must include 1"):
        fit_response([0.0, 0.5], [img, img])
    with pytest.raises(InputError, match="must include 0 and 1"):
        fit_response([0.25, 0.5], [img, img])
    with pytest.raises(InputError, match="strictly between 0 and 1"):
        fit_response([0.0, 1.0], [img, img])
    with pytest.raises(InputError, match="3 levels but 2 images"):
        fit_response([0.0, 0.5, 1.0], [img, img])
    with pytest.raises(InputError, match="only 0 pixel.*raise the exposure"):
        fit_response([0.0, 0.5, 1.0], [img, img, img])  # no contrast: the projector is off
    with pytest.raises(InputError, match=r"in \[0, 1\]"):
        fit_response([0.0, 0.5, 255], [img, img, img])
    sim = SimRig(default_scene("sphere"))
    with pytest.raises(InputError, match="repeat after rounding"):
        measure_response(sim.projector, sim.camera, levels=[0.0, 0.5, 0.501, 1.0])


# --------------------------------------------------------------------------- phase correction
@pytest.mark.parametrize("steps", [3, 4, 8])
@pytest.mark.parametrize("gamma", [2.2, 0.6])
def test_phase_correction_inverts_the_measured_phase(steps, gamma):
    phi = np.random.default_rng(0).uniform(0, 2 * np.pi, 20000)
    # Any affine camera response (a, b) per sample: the correction must not depend on it.
    a, b = np.random.default_rng(1).uniform(0.01, 0.2, (2, phi.size)) * [[1], [4]]
    frames = [(a + b * (0.5 + 0.5 * np.cos(phi - 2 * np.pi * s / steps)) ** gamma).astype(np.float32)
              for s in range(steps)]
    measured, _, _ = phase_from_steps(frames)
    corrected = phase_correction(ProjectorResponse(gamma), steps)(measured)
    err = lambda x: np.abs(np.angle(np.exp(1j * (x.astype(np.float64) - phi))))  # noqa: E731
    assert corrected.dtype == np.float32 and corrected.shape == phi.shape
    assert corrected.min() >= 0 and corrected.max() < 2 * np.pi
    assert err(corrected).max() < 2e-5
    if steps <= 4:
        assert err(measured).max() > 0.005  # the effect being corrected
    ident = phase_correction(1.0, steps)
    assert ident.max_offset < 1e-12 and np.array_equal(ident(measured), measured)


def test_phase_correction_refuses_what_it_cannot_invert():
    with pytest.raises(InputError, match="too strong for 3-step.*use more steps"):
        phase_correction(8.0, 3)
    with pytest.raises(InputError, match="steps must be an integer >= 3"):
        phase_correction(2.2, 2)
    with pytest.raises(InputError, match="gamma must be a finite number > 0"):
        phase_correction(-1.0, 4)


_TRUTH: dict = {}


def _phase_capture(method, options, gamma):
    """Columns-only capture of the tilted plane under ``gamma`` (same seed for every gamma) + truth."""
    key = (method, tuple(sorted(options.items())), gamma)
    if key not in _TRUTH:
        sim = SimRig(default_scene("plane"), imaging=ImagingModel(gamma=gamma), seed=3)
        spec = make_pattern_spec(method, sim.projector.resolution, axes=("columns",), **options)
        truth = sim.ground_truth()
        m = binary_erosion(truth.lit & (truth.object_id == 0), iterations=3)
        _TRUTH[key] = (np.stack(sim.capture_sequence(list(spec.frames()))), spec, truth.proj_col, m)
    return _TRUTH[key]


def _column_rms(method, options, gamma, response):
    imgs, spec, true_col, m = _phase_capture(method, options, gamma)
    res = decode(imgs, spec, subpixel=False, response=response)
    e = (res.proj_col - true_col)[m]
    return float(np.sqrt(np.nanmean(e ** 2))), float(np.isfinite(e).mean())


def test_three_step_phase_shifting_under_gamma_is_corrected():
    """Issue 7 acceptance: gamma 2.2 + correction within 1.5x of a linear projector's column error."""
    opts = {"steps": 3, "fine_steps": 3}
    response = default_rig().projector_response  # the simulator's true rig carries the true gamma
    assert response == ProjectorResponse(2.2)
    linear, dec1 = _column_rms("phase", opts, 1.0, None)
    raw, _ = _column_rms("phase", opts, 2.2, None)
    corrected, dec2 = _column_rms("phase", opts, 2.2, response)
    print(f"\n3-step phase, plane, column RMS: gamma 1: {linear:.4f} px; gamma 2.2 uncorrected: {raw:.4f} px; "
          f"corrected: {corrected:.4f} px ({corrected / linear:.2f}x); decoded {dec1:.4f} / {dec2:.4f}")
    assert dec1 > 0.995 and dec2 > 0.995
    assert corrected <= 1.5 * linear        # measured 1.19x
    assert raw > 3 * linear                 # measured 15x (0.60 px of bending, and unwrapping errors)
    # A linear response changes nothing, bit for bit.
    imgs, spec, _, _ = _phase_capture("phase", opts, 2.2)
    a, b = decode(imgs, spec, subpixel=False), decode(imgs, spec, subpixel=False, response=ProjectorResponse(1.0))
    np.testing.assert_array_equal(a.proj_col, b.proj_col)
    with pytest.raises(DecodeError, match="ProjectorResponse"):
        decode(imgs, spec, response=2.2)


# --------------------------------------------------------------------------- rig file
def test_rig_file_round_trip_with_projector_response(tmp_path):
    rig = default_rig()
    assert rig.to_dict()["projector_response"] == {"gamma": 2.2}
    save_rig(rig, tmp_path / "rig.json")
    back = load_rig(tmp_path / "rig.json")
    assert back.projector_response == ProjectorResponse(2.2)
    assert back.to_dict() == rig.to_dict()
    # Optional: the template leaves it null (not measured), and a file without it loads as None.
    data = template_rig()
    assert data["projector_response"] is None
    assert Rig.from_dict(data).projector_response is None
    del data["projector_response"]
    assert Rig.from_dict(data).projector_response is None


@pytest.mark.parametrize("value,message", [
    ({"gamma": -2.2}, r"rig.json: projector_response.gamma: must be a finite number > 0 .* found -2.2"),
    ({"gamma": "2.2"}, r"rig.json: projector_response.gamma: must be a finite number > 0 .* found '2.2'"),
    ({"gamma": 0}, r"rig.json: projector_response.gamma: must be a finite number > 0"),
    ({"gamma": True}, r"rig.json: projector_response.gamma: must be a finite number > 0"),
    ({}, r"rig.json: projector_response: missing field 'gamma'"),
    ({"gamma": 2.2, "offset": 0.1}, r"rig.json: projector_response: unknown field\(s\) 'offset'"),
    (2.2, r"rig.json: projector_response: must be an object \{\"gamma\": number\} or null, found 2.2"),
])
def test_rig_file_projector_response_errors_name_the_field(tmp_path, value, message):
    file = tmp_path / "rig.json"
    file.write_text(json.dumps(dict(template_rig(), projector_response=value)))
    with pytest.raises(ConfigError, match=message):
        load_rig(file)
