"""``rangekit check``: look before scanning, on the simulator or on hardware.

Steps (the devices: ``camera``, ``projector``, and optionally ``sleep``/``clock`` of the simulator):

1. The rig's camera controls are applied (auto-exposure: the default 33333 us is locked for the check).
2. White, black and a checker are projected (each after :data:`SETTLE_S` on the devices' clock) and
   captured: per-channel saturation, dark fraction, the contrast histogram (:mod:`.check_stats`).
3. Suggested exposure: the white capture is repeated at 1/4, 1/16 ... of the exposure until the 99th
   percentile of white on the object is below full scale, and the exposure scaled so that it sits at
   90% of full scale (:data:`~.check_stats.TARGET_P99`), rounded to whole projector refresh periods.
4. Latency: black, a capture to settle, then white shown at ``t0``; consecutive frames are captured and
   the first whose mean moved by more than half the white-black step gives ``latency = frame time - t0``
   (``camera.last_frame_time`` when the camera has it, else the clock when ``capture`` returned); three
   times, the largest kept. ``pattern_delay_s`` = latency rounded up to whole frame periods, plus one. Frames
   are read with ``camera.unflushed_frame()`` when the camera has it (a UVC webcam: the next frame of its driver's
   queue, none dropped), else ``capture()``.
5. Flush frames: black, then white shown and ``pattern_delay_s`` waited, as a scan waits; the frames read that
   still show black are the stale frames a driver queues (a UVC webcam's 2-4), three times, the largest kept: a
   capture must drop that many (the camera's ``flush_frames``, set for the test view; ``rangekit check --rig``
   writes it into ``devices.camera.flush_frames`` where the camera type has that field). 0 for a camera whose
   ``capture`` returns only frames exposed after the call (the simulator's, depthai's).
6. One coded-light view captured with that delay and reconstructed as a test.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

import numpy as np

from rangekit.app.check.stats import DARK_TARGET, TARGET_P99, ImageStats, image_stats, lit_mask
from rangekit.rig.camera_controls import CONTROL_FIELDS, CameraControls, round_to_refresh
from rangekit.rig.checks import MAX_FLUSH_FRAMES
from rangekit.errors import DeviceError

__all__ = ["SETTLE_S", "CheckResult", "run_check", "measure_latency", "measure_flush_frames", "pattern_delay_for",
           "auto_exposures", "exposures_from_check"]

#: Wait after showing a pattern before a settled capture (seconds, the devices' clock): longer than any
#: projector's latency.
SETTLE_S = 1.0
#: The coded-light decoder's confidence threshold (rangekit.coded.reconstruct.reconstruct_view's default).
MIN_CONFIDENCE = 0.03
_MIN_US, _MAX_US = CONTROL_FIELDS["exposure_us"][:2]


@dataclass(frozen=True)
class CheckResult:
    """What ``rangekit check`` measured; fractions of full scale, times in seconds, exposures in us."""

    exposure_us: float
    stats: ImageStats
    suggested_exposure_us: float
    dark_exposure_us: float           # the exposure that lifts the dark parts (5th percentile of contrast to 10%)
    latency_s: float
    latencies_s: tuple
    frame_period_s: float
    pattern_delay_s: float
    checker_contrast: float           # |checker - mid| / half the white-black step on the object, ~1 in focus
    points: int = 0
    rms_m: float | None = None
    flush_frames: int = 0             # stale frames after a pattern change and the pattern delay: a capture drops them
    flush_counts: tuple = ()          # each of the three measurements

    def to_dict(self) -> dict:
        """check.json."""
        s = self.stats
        return {"latency_s": self.latency_s, "latencies_s": list(self.latencies_s),
                "saturated_fraction": s.saturated_fraction, "dark_fraction": s.dark_fraction,
                "suggested_exposure_us": self.suggested_exposure_us, "exposure_us": self.exposure_us,
                "dark_exposure_us": self.dark_exposure_us, "channel_saturation": s.channel_saturation,
                "contrast_percentiles": s.contrast_percentiles, "contrast_histogram": {
                    "counts": s.histogram[0], "edges": s.histogram[1]},
                "white_p99": s.white_p99, "object_pixels": s.n_object, "frame_period_s": self.frame_period_s,
                "pattern_delay_s": self.pattern_delay_s, "flush_frames": self.flush_frames,
                "flush_counts": list(self.flush_counts), "checker_contrast": self.checker_contrast,
                "test_view": {"points": self.points, "rms_m": self.rms_m}}

    def advice(self) -> list[str]:
        """What to change, one line each."""
        s, e, lines = self.stats, self.exposure_us, []
        if s.saturated_fraction > 0.001:
            lines.append(f"exposure {e:.0f} us saturates {s.saturated_fraction:.1%} of the object: use "
                         f"{self.suggested_exposure_us:.0f} us (or scan with --exposures auto)")
        elif self.suggested_exposure_us > 1.5 * e:
            lines.append(f"exposure {e:.0f} us uses {s.white_p99:.0%} of full scale: use "
                         f"{self.suggested_exposure_us:.0f} us")
        else:
            lines.append(f"exposure {e:.0f} us is right (99% of the object below {s.white_p99:.0%} of full scale)")
        if s.dark_fraction > 0.05:
            lines.append(f"{s.dark_fraction:.1%} of the object is too dark to decode (white - black below "
                         f"{MIN_CONFIDENCE:.0%} of full scale): {self.dark_exposure_us:.0f} us lifts it "
                         "(scan with --exposures auto)")
        lines.append(f"latency {self.latency_s * 1e3:.0f} ms: pattern_delay_s set to {self.pattern_delay_s:g}")
        if self.flush_frames:
            lines.append(f"{self.flush_frames} frame(s) queued by the camera's driver still show the old pattern after "
                         f"the delay: each capture drops them (flush_frames {self.flush_frames})")
        return lines


def _clock(devices):
    clock = getattr(devices, "clock", None)
    now = clock.now if clock is not None else time.monotonic
    return now, getattr(devices, "sleep", time.sleep)


def _shot(devices, pattern, settle_s: float = SETTLE_S) -> np.ndarray:
    _, sleep = _clock(devices)
    devices.projector.show(pattern)
    sleep(settle_s)
    devices.camera.capture()            # a frame that may have started before the wait: dropped
    return np.asarray(devices.camera.capture())


def _flat(devices, value: int) -> np.ndarray:
    W, H = devices.projector.resolution
    return np.full((H, W), value, np.uint8)


def _checker(devices, square: int = 32) -> np.ndarray:
    W, H = devices.projector.resolution
    yy, xx = np.mgrid[0:H, 0:W]
    return (((yy // square + xx // square) % 2) * 255).astype(np.uint8)


def pattern_delay_for(latency_s: float, frame_period_s: float) -> float:
    """The latency rounded up to a whole number of frame periods, plus one period (seconds)."""
    n = math.ceil(latency_s / frame_period_s - 1e-6) + 1
    return round(n * frame_period_s, 6)


def _black_and_step(devices) -> tuple[float, float]:
    """The settled black frame's mean and the white-black step; DeviceError when the camera does not see the
    projector."""
    black = _shot(devices, _flat(devices, 0)).astype(np.float64).mean()
    white = _shot(devices, _flat(devices, 255)).astype(np.float64).mean()
    step = white - black
    if not step > 0.5:
        raise DeviceError(f"camera: its mean brightness does not change between the projector's black and white "
                          f"({black:.1f} and {white:.1f}); aim the projector at the object and check that it shows "
                          "the patterns")
    return black, step


def measure_flush_frames(devices, delay_s: float, *, repeats: int = 3) -> tuple[int, ...]:
    """The frames that still show the old pattern after a pattern change and ``delay_s`` seconds (module docstring,
    step 5), measured ``repeats`` times. DeviceError when more than MAX_FLUSH_FRAMES do."""
    _, sleep = _clock(devices)
    cam = devices.camera
    black, step = _black_and_step(devices)
    read = getattr(cam, "unflushed_frame", cam.capture)
    out = []
    for _ in range(repeats):
        _shot(devices, _flat(devices, 0))
        devices.projector.show(_flat(devices, 255))
        sleep(delay_s)
        stale = 0
        while np.asarray(read()).astype(np.float64).mean() - black <= step / 2:
            stale += 1
            if stale > MAX_FLUSH_FRAMES:
                raise DeviceError(f"camera: {stale} frames after the projector showed white and {delay_s:g} s still "
                                  "show black; check the projector's input and the camera's frame rate")
        out.append(stale)
    return tuple(out)


def measure_latency(devices, *, repeats: int = 3, max_s: float = SETTLE_S) -> tuple[float, ...]:
    """The projector-to-camera latency (seconds), measured ``repeats`` times (module docstring, step 4).
    DeviceError when the camera does not see the projector or no frame changes within ``max_s``."""
    now, sleep = _clock(devices)
    cam = devices.camera
    black, step = _black_and_step(devices)
    read = getattr(cam, "unflushed_frame", cam.capture)
    out = []
    for _ in range(repeats):
        _shot(devices, _flat(devices, 0))
        t0 = now()
        devices.projector.show(_flat(devices, 255))
        while True:
            frame = np.asarray(read()).astype(np.float64).mean()
            t = getattr(cam, "last_frame_time", None)
            t = now() if t is None else t
            if frame - black > step / 2:
                out.append(max(0.0, t - t0))
                break
            if t - t0 > max_s:
                raise DeviceError(f"camera: no frame changed within {max_s:g} s of the projector showing white; "
                                  "check the projector's input")
    return tuple(out)


def _suggest(devices, controls: CameraControls, stats: ImageStats, mask, full_scale, refresh_hz) -> float:
    """The exposure putting the object's 99th percentile of white at TARGET_P99 (module docstring, step 3)."""
    e, p99 = controls.exposure_us, stats.white_p99
    white = _flat(devices, 255)
    set_controls = getattr(devices.camera, "set_controls", None)
    while p99 >= 1.0 and set_controls is not None and e / 4 >= _MIN_US:
        e /= 4
        set_controls(replace(controls, exposure_us=e))
        img = np.asarray(_shot(devices, white), dtype=np.float32) / np.float32(full_scale)
        p99 = float(np.percentile((img.max(axis=2) if img.ndim == 3 else img)[mask], 99))
    if set_controls is not None and e != controls.exposure_us:
        set_controls(controls)
    scale = TARGET_P99 / max(p99, 1e-3) if p99 < 1.0 else 0.25
    return round_to_refresh(min(max(e * scale, _MIN_US), _MAX_US), refresh_hz)


def auto_exposures(suggested_us: float, fps: float, n: int = 3) -> tuple[int, ...]:
    """``--exposures auto``: ``n`` exposures 4x apart, the longest ``4**(n-1)`` times the highlights'
    exposure (``suggested_us``) but at most one frame period (``1e6 / fps``), so the shortest never
    saturates the highlights and the longest lifts the dark parts as far as the frame rate allows."""
    top = min(suggested_us * 4 ** (n - 1), 1e6 / fps)
    return tuple(int(round(max(top / 4 ** k, _MIN_US))) for k in reversed(range(n)))


def _exposure_stats(devices, rig, controls: CameraControls, full_scale: float, mask=None):
    """Steps 1-3 of the module docstring: (controls used, white, black, mask, stats, suggested us, dark us)."""
    if controls.auto_exposure:
        controls = replace(controls, exposure_us=CameraControls().exposure_us)
    set_controls = getattr(devices.camera, "set_controls", None)
    if set_controls is not None:
        set_controls(controls)
    white, black = _shot(devices, _flat(devices, 255)), _shot(devices, _flat(devices, 0))
    mask = lit_mask(white, black, full_scale) if mask is None else np.asarray(mask, dtype=bool)
    stats = image_stats(white, black, full_scale, mask, MIN_CONFIDENCE)
    refresh = ((rig.devices or {}).get("projector") or {}).get("refresh_hz")
    suggested = _suggest(devices, controls, stats, mask, full_scale, refresh)
    p5 = max(stats.contrast_percentiles["p5"], 1e-3)
    dark = round_to_refresh(min(controls.exposure_us * DARK_TARGET / p5, _MAX_US), refresh)
    return controls, white, black, mask, stats, suggested, dark


def exposures_from_check(devices, rig, controls: CameraControls, full_scale: float) -> tuple[int, ...]:
    """``rangekit scan --exposures auto``: check's suggested exposures for the highlights and the dark parts
    measured on ``devices``, made into :func:`auto_exposures`."""
    controls, *_, suggested, _ = _exposure_stats(devices, rig, controls, full_scale)
    return auto_exposures(suggested, controls.fps)


def run_check(devices, rig, controls: CameraControls, *, full_scale: float, mask=None, truth=None,
              spec=None, progress=None) -> tuple[CheckResult, dict]:
    """Run the check on opened ``devices`` (see the module docstring).

    ``mask``: (H, W) bool object pixels (default: the projector-lit pixels, :func:`lit_mask`); ``truth``:
    the simulator's ViewGeometry, for the test view's RMS; ``spec``: the test view's PatternSpec (default
    the Gray code + phase shift of a scan). Returns the result and the images (white, black, checker,
    mask) for the figure.
    """
    from rangekit.progress import call_progress

    if controls.auto_exposure:
        call_progress(progress, "the rig's exposure is auto: the check locks it at 33333 us (set it in the rig file)")
    call_progress(progress, "white, black and checker")
    controls, white, black, mask, stats, suggested, dark = _exposure_stats(devices, rig, controls, full_scale, mask)
    checker = _shot(devices, _checker(devices))
    mid = (white.astype(np.float64) + black) / 2
    half = np.maximum((white.astype(np.float64) - black) / 2, 1.0)
    cc = np.abs(checker - mid) / half
    checker_contrast = float(np.median((cc.mean(axis=2) if cc.ndim == 3 else cc)[mask])) if mask.any() else 0.0
    call_progress(progress, "projector latency")
    latencies = measure_latency(devices)
    period = 1.0 / controls.fps
    latency = max(latencies)
    delay = pattern_delay_for(latency, period)
    call_progress(progress, "frames queued after a pattern change")
    flush_counts = measure_flush_frames(devices, delay)
    if hasattr(devices.camera, "flush_frames"):
        devices.camera.flush_frames = max(flush_counts)
    points, rms = _test_view(devices, rig, spec, delay, full_scale, truth, progress)
    result = CheckResult(float(controls.exposure_us), stats, suggested, dark, latency, latencies, period, delay,
                         checker_contrast, points, rms, flush_frames=max(flush_counts), flush_counts=flush_counts)
    return result, {"white": white, "black": black, "checker": checker, "mask": mask}


def _test_view(devices, rig, spec, delay: float, full_scale: float, truth, progress) -> tuple[int, float | None]:
    """One coded-light view captured with ``delay`` after each pattern and reconstructed: (points, RMS
    against ``truth`` in metres, or None)."""
    from rangekit.coded.reconstruct import reconstruct_view
    from rangekit.coded.patterns import make_pattern_spec
    from rangekit.progress import call_progress

    _, sleep = _clock(devices)
    spec = spec or make_pattern_spec("hybrid", (rig.projector.width, rig.projector.height))
    call_progress(progress, f"test view: {spec.n_frames} {spec.method} frames")
    images = []
    for pattern in spec.frames():
        devices.projector.show(pattern)
        sleep(delay)
        images.append(np.asarray(devices.camera.capture()))
    rec = reconstruct_view(images, spec, rig.camera, rig.projector, full_scale=full_scale,
                           response=rig.projector_response, min_confidence=MIN_CONFIDENCE)
    valid = rec.triangulated.valid
    rms = None
    if truth is not None:
        ok = valid & truth.hit
        d = rec.triangulated.xyz[ok] - truth.xyz[ok]
        rms = float(np.sqrt(np.mean(np.sum(d * d, axis=1)))) if ok.any() else None
    return int(valid.sum()), rms

