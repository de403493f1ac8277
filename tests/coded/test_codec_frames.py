"""The fringe codecs' frames are the tools' own, value for value (issue 35): each tool's formula is written out
here from its source, in its precision and with its rounding, and compared with what the rangekit spec
generates, in the tool's frame order. A capture layout preset can then decode the tool's folder as it lies
on disk, and the simulator renders what the tool projects.

Sources: SLStudio (github jakobwilm/slstudio) ``src/codec/pstools.cpp`` (``computePhaseVector``),
``CodecPhaseShiftMicro.cpp``, ``CodecPhaseShiftModulated.cpp``, ``CodecPhaseShift2x3.cpp``,
``CodecPhaseShiftNStep.cpp``, ``CodecPhaseShift3.cpp``, ``CodecPhaseShift3FastWrap.cpp``,
``CodecPhaseShift4.cpp``; OpenCV contrib ``modules/structured_light/src/sinusoidalpattern.cpp``
(``SinusoidalPattern::generate``).
"""

from __future__ import annotations

import numpy as np
import pytest

from rangekit.coded.patterns import PatternSpec
from rangekit.errors import PatternError

PI = np.float32(np.pi)        # const float pi = M_PI
SCREEN = (1824, 1140)         # the projector of SLStudio's skull data


def _cosf(x: np.ndarray) -> np.ndarray:
    """C's float cos of a float argument (correctly rounded)."""
    return np.cos(np.asarray(x, np.float32).astype(np.float64)).astype(np.float32)


def _compute_phase_vector(length: int, phase, pitch) -> np.ndarray:
    """pstools::computePhaseVector: float amp = 0.5*(1+cos(2*pi*i/pitch - phase)); Vec3b(255.0*amp) truncates."""
    i = np.arange(length).astype(np.float32)
    arg = np.float32(2) * PI * i / np.float32(pitch) - np.float32(phase)      # float arithmetic, left to right
    amp = (0.5 * (np.float32(1) + _cosf(arg)).astype(np.float64)).astype(np.float32)
    return np.trunc(255.0 * amp.astype(np.float64)).astype(np.uint8)


def _rows(line: np.ndarray, height: int) -> np.ndarray:
    return np.tile(line, (height, 1))


def test_slstudio_micro_phase_shifting_frames():
    """EncoderPhaseShiftMicro: 3 steps of frequencies[0] at phase -2 pi/3 i, then one frame per other pitch at
    phase pi (odd index) or 0 (even); 12 frames."""
    W, H = SCREEN
    pitches = [75.02, 70.00, 71.32, 72.47, 73.72, 76.23, 77.35, 78.40, 79.22, 80.00]
    tool = [_compute_phase_vector(W, np.float32(-2.0 * float(PI) / 3.0 * i), np.float32(pitches[0])) for i in range(3)]
    tool += [_compute_phase_vector(W, PI if i % 2 else np.float32(0.0), np.float32(pitches[i])) for i in range(1, 10)]
    spec = PatternSpec("micro", W, H, ("columns",))
    assert spec.n_frames == 12
    for k, (name, frame) in enumerate(zip(spec.frame_names, spec.frames())):
        assert np.array_equal(frame, _rows(tool[k], H)), f"frame {k} ({name})"


def test_slstudio_modulated_phase_shifting_frames():
    """EncoderPhaseShiftModulated (USE_SINE_MODULATOR, slstudio f49eec5): Lx (pitch cols/nPhaseX, 24) x My (pitch
    rows/nPhaseY, 16, across rows),
    cv::multiply(Lx, My, I, 255, CV_8U) for x outer, y inner; then 3 cue steps of one period
    (computePhaseVector); 12 frames."""
    W, H = SCREEN

    def amp(n, pitch, phase):  # float phase = 2 * pi * c / pitch - phaseX; float amp = 0.5 + 0.5 * cos(phase)
        c = np.arange(n).astype(np.float32)
        return (0.5 + 0.5 * _cosf(np.float32(2) * PI * c / pitch - phase).astype(np.float64)).astype(np.float32)

    step = [np.float32(2) * PI / np.float32(3) * np.float32(i) for i in range(3)]   # 2 * pi / Nx * x, float
    Lx = [amp(W, np.float32(W) / np.float32(24), step[x]) for x in range(3)]
    My = [amp(H, np.float32(H) / np.float32(16), step[y]) for y in range(3)]
    tool = [np.rint(np.float32(255) * Lx[x][None, :] * My[y][:, None]).astype(np.uint8)
            for x in range(3) for y in range(3)]
    tool += [_rows(_compute_phase_vector(W, np.float32(2.0 * float(PI) / 3 * i), np.float32(W)), H) for i in range(3)]
    spec = PatternSpec("modulated", W, H, ("columns",))
    assert spec.n_frames == 12
    for k, (name, frame) in enumerate(zip(spec.frame_names, spec.frames())):
        assert np.array_equal(frame, tool[k]), f"frame {k} ({name})"


@pytest.mark.parametrize("codec,periods,steps,fine_steps,tool_order", [
    # CodecPhaseShift2x3: 00-02 pitch cols/16 (nPhases 16), 03-05 the cue of one period
    ("2x3", lambda W: [W, W / 16], 3, 3, lambda W: [(W / 16, 3, k) for k in range(3)] + [(W, 3, k) for k in range(3)]),
    # CodecPhaseShiftNStep: 00-08 nine steps of pitch cols/8, 09-11 the cue
    ("NStep", lambda W: [W, W / 8], 3, 9, lambda W: [(W / 8, 9, k) for k in range(9)] + [(W, 3, k) for k in range(3)]),
    # CodecPhaseShift3FastWrap and CodecPhaseShift4: N steps of one period across the screen
    ("3FastWrap", lambda W: [W], 3, 3, lambda W: [(W, 3, k) for k in range(3)]),
    ("4", lambda W: [W], 4, 4, lambda W: [(W, 4, k) for k in range(4)]),
])
def test_slstudio_phase_codecs_are_rangekits_phase_rounded_down(codec, periods, steps, fine_steps, tool_order):
    """computePhaseVector(cols, 2.0*pi/N * i, pitch) for each of the tool's files, against the frame of the
    same period and step of a ``phase`` spec with ``rounding: "down"``."""
    W, H = SCREEN
    spec = PatternSpec("phase", W, H, ("columns",), {"periods": periods(W), "steps": steps,
                                                       "fine_steps": fine_steps, "rounding": "down"})
    for k, (pitch, n, s) in enumerate(tool_order(W)):
        tool = _compute_phase_vector(W, np.float32(2.0 * float(PI) / n * s), np.float32(pitch))
        ours = spec.frame_by_name(f"col_p{pitch:g}_s{s}")
        assert np.array_equal(ours, _rows(tool, H)), f"SLStudio {codec} file {k:02d}"
    # Rounded to nearest (the default) the same spec differs by at most one level.
    nearest = PatternSpec("phase", W, H, ("columns",), {"periods": periods(W), "steps": steps,
                                                          "fine_steps": fine_steps})
    for a, b in zip(nearest.frames(), spec.frames()):
        assert np.abs(a.astype(int) - b).max() <= 1


def test_slstudio_phase_shift3_is_single_period_phase():
    """EncoderPhaseShift3: float amp = 0.5*(1+cos(2*pi*i/pitch - phase)), pitch = cols, phase = 2 pi/3 i, plus
    Gaussian noise of std 0.05, convertTo(CV_8U, 255.0) (rounded). Without its noise, rangekit's single-period
    ``phase`` (fine_steps 3, rounded to nearest) agrees within one level, on 4 of 5472 values."""
    W, H = SCREEN
    spec = PatternSpec("phase", W, H, ("columns",), {"periods": [W], "fine_steps": 3})
    assert spec.frame_names[2:] == [f"col_p{W}_s{k}" for k in range(3)]
    diffs = 0
    for k in range(3):
        i = np.arange(W).astype(np.float32)
        arg = np.float32(2) * PI * i / np.float32(W) - np.float32(2.0 * float(PI) / 3 * k)
        amp = (0.5 * (np.float32(1) + _cosf(arg)).astype(np.float64)).astype(np.float32)
        tool = np.rint(amp * np.float32(255)).astype(np.uint8)
        d = spec.frame(2 + k)[0].astype(int) - tool
        assert np.abs(d).max() <= 1
        diffs += np.count_nonzero(d)
    assert diffs <= 0.001 * 3 * W


def _opencv_row(n: int, n_periods: int, i: int, shift=np.float32(2 * np.pi / 3)) -> np.ndarray:
    """SinusoidalPattern::generate: period = width / nbrOfPeriods (int); frequency = (float) 1 / period;
    saturate_cast<uchar>(meanAmpl + sinAmpl * sin(2 * CV_PI * frequency * j + i * params.shiftValue))."""
    period = n // n_periods
    frequency = np.float32(1) / np.float32(period)
    j = np.arange(n, dtype=np.float64)
    value = np.float32(127.5) + np.float32(127.5) * np.sin(2 * np.pi * np.float64(frequency) * j
                                                           + np.float64(np.float32(i) * shift))
    return np.clip(np.rint(value), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("method", ["ftp", "psp", "faps"])
@pytest.mark.parametrize("size,n_periods", [((800, 600), 20), ((1280, 800), 20), ((1280, 800), 7)])
def test_opencv_sinusoidal_pattern_frames(method, size, n_periods):
    """OpenCV's three frames (FTP reads frame 0 only), vertical fringes (horizontal = false) and horizontal ones
    (horizontal = true: period = height / nbrOfPeriods, the values along the rows); then the cue: the same
    generate() with nbrOfPeriods 1."""
    W, H = size
    spec = PatternSpec(method, W, H, ("columns", "rows"), {"n_periods": n_periods})
    n_fringe = 1 if method == "ftp" else 3
    frames = dict(zip(spec.frame_names, spec.frames()))
    assert len(frames) == 2 * (n_fringe + 3)
    for i in range(n_fringe):
        assert np.array_equal(frames[f"col_fringe_s{i}"], _rows(_opencv_row(W, n_periods, i), H))
        assert np.array_equal(frames[f"row_fringe_s{i}"], _rows(_opencv_row(H, n_periods, i), W).T)
    for i in range(3):
        assert np.array_equal(frames[f"col_cue_s{i}"], _rows(_opencv_row(W, 1, i), H))
        assert np.array_equal(frames[f"row_cue_s{i}"], _rows(_opencv_row(H, 1, i), W).T)
    without_cue = PatternSpec(method, W, H, ("columns",), {"n_periods": n_periods, "cue": False})
    assert without_cue.frame_names == [f"col_fringe_s{i}" for i in range(n_fringe)]


@pytest.mark.parametrize("method,options,message", [
    ("micro", {"periods": [75.0]}, "micro periods must be 2 to 16 numbers"),
    ("micro", {"periods": "75"}, "micro periods must be"),
    ("modulated", {"n_periods": 0}, "modulated n_periods"),
    ("modulated", {"carrier_n_periods": 2.5}, "modulated carrier_n_periods"),
    ("psp", {"shift": 0.0}, "psp shift must be a phase step in radians"),
    ("faps", {"n_periods": 10**6}, "faps n_periods"),
    ("ftp", {"cue": "yes"}, "ftp cue must be true or false"),
    ("phase", {"rounding": "up"}, "phase rounding must be one of nearest, down"),
])
def test_bad_codec_options_are_refused_naming_the_option(method, options, message):
    with pytest.raises(PatternError, match=message):
        PatternSpec(method, 1280, 800, ("columns",), options)


def test_codec_specs_round_trip_through_json():
    for method in ("micro", "modulated", "ftp", "psp", "faps"):
        spec = PatternSpec(method, 640, 400)
        assert PatternSpec.from_dict(spec.to_dict()) == spec
        assert spec.frame(spec.n_frames - 1).shape == (400, 640)
