"""The simulated camera's sensor: exposure, ISO gain, shot and read noise, full well, auto-exposure.

:class:`rangekit.sim.imaging.render.ViewRenderer` computes the irradiance of each pixel as ``E``, the fraction of
the full well that the reference controls collect (``ImagingModel.gain`` is that fraction for white light
on albedo 1 facing the projector at ``ref_distance``). The reference controls are ``CameraControls()``'s
exposure and ISO: :data:`REF_EXPOSURE_US` = 33333 us at :data:`REF_ISO` = 100, so the default controls
record the images the simulator recorded before it had controls, byte for byte. For other controls::

    electrons = E * full_well * exposure_us / REF_EXPOSURE_US            (irradiance x time x QE)
    electrons += N(0, electrons + read_noise^2)                          (shot noise, Poisson as its normal
                                                                          approximation, and read noise)
    electrons = clip(electrons, 0, full_well)                            (the full well)
    DN = rint(clip(electrons / full_well * (iso / REF_ISO) * max_value, 0, max_value))

so the ISO gain multiplies the signal and the read noise alike (it acts after the noise), and raises the
clipping point below the full well when the ADC saturates first.

**Auto-exposure** (``controls.exposure_us`` None). The camera controls one exposure value
``x = exposure_us * iso / REF_ISO`` (microsecond-equivalents at ISO 100), as depthai's auto-exposure
controls exposure and ISO together: the exposure takes ``x`` up to the frame period ``1e6 / fps``, the
ISO gain the rest (up to :data:`AE_MAX_ISO`). After each frame, with ``m`` that frame's mean digital value
as a fraction of full scale over the whole image, ``log x`` moves :data:`AE_RATE` of the way towards the
exposure that would give :data:`AE_TARGET` (18% of full scale: middle grey)::

    log x  <-  log x + AE_RATE * log(AE_TARGET / max(m, 1 / max_value))

It starts from the controls' ISO (100 when auto) at the reference exposure, or from the exposure the
camera had. The state is the camera's own and changes only with captures, so the same sequence of calls
gives the same bytes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rangekit.rig.camera_controls import CONTROL_FIELDS, CameraControls
from rangekit.sim.imaging._kernels import noise_and_adc

__all__ = ["REF_EXPOSURE_US", "REF_ISO", "AE_TARGET", "AE_RATE", "AE_MAX_ISO", "Exposure", "exposure_for",
           "auto_exposure_step", "digitise", "noise_std", "saturated"]

REF_EXPOSURE_US: float = CameraControls().exposure_us
REF_ISO: int = CameraControls().iso
#: Auto-exposure's target: the mean of the image at 18% of full scale (middle grey).
AE_TARGET = 0.18
#: The fraction of the way (in log exposure) auto-exposure moves after each frame.
AE_RATE = 0.5
#: Auto-exposure's highest ISO (the rig file's largest).
AE_MAX_ISO = CONTROL_FIELDS["iso"][1]
_MIN_EXPOSURE_US = CONTROL_FIELDS["exposure_us"][0]


@dataclass(frozen=True)
class Exposure:
    """The exposure (microseconds) and ISO of one frame."""

    exposure_us: float = REF_EXPOSURE_US
    iso: float = REF_ISO

    @property
    def ratio(self) -> float:
        """Electrons collected relative to the reference exposure."""
        return self.exposure_us / REF_EXPOSURE_US

    @property
    def iso_gain(self) -> float:
        return self.iso / REF_ISO


def exposure_for(value_us: float, fps: float) -> Exposure:
    """Auto-exposure's split of an exposure value (us at ISO 100) into exposure (at most a frame period)
    and ISO gain (at most :data:`AE_MAX_ISO`)."""
    period_us = 1e6 / fps
    x = min(max(value_us, _MIN_EXPOSURE_US), period_us * AE_MAX_ISO / REF_ISO)
    exposure = min(x, period_us)
    return Exposure(float(exposure), REF_ISO * x / exposure)


def auto_exposure_step(value_us: float, mean: float, max_value: int) -> float:
    """The exposure value (us at ISO 100) after a frame whose mean is ``mean`` (fraction of full scale)."""
    m = max(float(mean), 1.0 / max_value)
    return float(value_us * math.exp(AE_RATE * math.log(AE_TARGET / m)))


def digitise(signal: np.ndarray, model, exposure: Exposure, rng: np.random.Generator) -> np.ndarray:
    """Signal ``E`` (full-scale fractions at the reference controls, float32; modified in place) -> the
    quantised image at ``exposure`` (see the module docstring). ``model``: an ImagingModel."""
    img = np.ascontiguousarray(signal, dtype=np.float32)
    if exposure.ratio != 1.0:
        img *= np.float32(exposure.ratio)
    # One compiled pass (sim/imaging/_kernels.py), the same float32 operations as numpy's:
    #   std = sqrt(max(img, 0) * full_well + read_noise^2); img += std * N(0, 1) / full_well
    #   iso gain: clip(img, 0, 1) (the full well), img *= max_value * iso_gain; else img *= max_value (the
    #   reference: full well and ADC clip together); then clip(img, 0, max_value) and round half to even.
    z = rng.standard_normal(img.shape, dtype=np.float32).reshape(-1) if model.full_well > 0 else None
    out = np.empty(img.shape, model.dtype)
    noise_and_adc(img.reshape(-1), z, np.float32(model.full_well), np.float32(model.read_noise ** 2),
                  exposure.iso_gain != 1.0, np.float32(model.max_value * exposure.iso_gain),
                  np.float32(model.max_value), out.reshape(-1))
    return out


def noise_std(model, signal: np.ndarray, exposure: Exposure) -> np.ndarray:
    """Standard deviation of the recorded value, in full-scale fractions, for the reference signal
    ``signal`` at ``exposure`` (shot + read noise times the ISO gain; before quantisation and clipping)."""
    s = np.maximum(np.asarray(signal, dtype=np.float64), 0) * exposure.ratio
    if model.full_well == 0:
        return np.zeros_like(s)
    return np.sqrt(s * model.full_well + model.read_noise ** 2) / model.full_well * exposure.iso_gain


def saturated(signal: np.ndarray, model, exposure: Exposure) -> np.ndarray:
    """Where the noise-free image of the reference signal ``signal`` (full-scale fractions, (H, W[, 3]))
    reaches full scale at ``exposure``: the truth a saturation measurement is compared against. The image
    :func:`digitise` records without noise is ``rint(min(signal * ratio, 1) * iso_gain * max_value)``
    clipped at ``max_value``, so a pixel is at full scale when ``signal * ratio * iso_gain`` is at least
    ``(max_value - 0.5) / max_value`` (and the full well is reached)."""
    s = np.asarray(signal, dtype=np.float64) * exposure.ratio
    level = (model.max_value - 0.5) / model.max_value
    return np.minimum(s, 1.0) * exposure.iso_gain >= level
