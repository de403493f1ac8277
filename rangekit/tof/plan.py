"""The light and its modulation: the speed of light and the plan of a continuous-wave ToF frame
(modulation frequencies and the phase steps sampled at each, in the order raw samples come in)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import reduce

import numpy as np

from rangekit.errors import InputError, shown

__all__ = ["C_LIGHT", "FREQUENCY_RANGE_HZ", "FrequencyPlan", "MAX_FREQUENCIES", "MAX_STEPS"]


#: Speed of light in vacuum, m/s (exact by definition of the metre).
C_LIGHT = 299_792_458.0
#: The most modulation frequencies in a plan, and phase steps per frequency (real sensors use 2-3 and 3-4).
MAX_FREQUENCIES = 16
MAX_STEPS = 64
#: Modulation frequencies a continuous-wave ToF camera uses, Hz: 1 MHz unwraps 150 m, 1 GHz 15 cm (sensors: 10-320
#: MHz). ``rangekit sim render --frequencies-mhz`` refuses others.
FREQUENCY_RANGE_HZ = (1e6, 1e9)


@dataclass(frozen=True)
class FrequencyPlan:
    """Modulation frequencies and the phase steps sampled at each: the order raw samples come in.

    Samples are frequency-major: all steps of ``frequencies[0]``, then all of ``frequencies[1]``...

    frequencies : Hz, each > 0 (e.g. (16e6, 80e6, 120e6) as Kinect v2).
    steps : per frequency, the reference phase shifts ``theta_k`` in radians (at least 3 distinct ones
        modulo 2 pi), e.g. (0, 2 pi/3, 4 pi/3) for 3-bucket or (0, pi/2, pi, 3 pi/2) for 4-bucket.
    """

    frequencies: tuple[float, ...]
    steps: tuple[tuple[float, ...], ...]

    def __post_init__(self) -> None:
        f = tuple(float(v) for v in np.atleast_1d(np.asarray(self.frequencies, dtype=np.float64)))
        if not f or not all(math.isfinite(v) and v > 0 for v in f):
            raise InputError(f"FrequencyPlan: frequencies must be positive Hz values, found {self.frequencies!r}")
        if len(f) > MAX_FREQUENCIES or any(len(s) > MAX_STEPS for s in self.steps):
            raise InputError(f"FrequencyPlan: expected at most {MAX_FREQUENCIES} frequencies of at most {MAX_STEPS} "
                             f"phase steps each, found {len(f)} frequencies of "
                             f"{[len(s) for s in self.steps][:20]} steps")
        if len(set(f)) != len(f):
            raise InputError(f"FrequencyPlan: frequencies must be distinct, found {self.frequencies!r}")
        steps = tuple(tuple(float(t) for t in s) for s in self.steps)
        if len(steps) != len(f):
            raise InputError(f"FrequencyPlan: {len(f)} frequencies but {len(steps)} lists of phase steps")
        for fj, s in zip(f, steps):
            wrapped = np.round(np.mod(s, 2 * np.pi), 9) % round(2 * np.pi, 9)
            if len(s) < 3 or len(set(wrapped.tolist())) < 3 or not all(math.isfinite(t) for t in s):
                raise InputError(f"FrequencyPlan: {fj / 1e6:g} MHz needs at least 3 distinct phase steps "
                                 f"(radians), found {s!r}")
        object.__setattr__(self, "frequencies", f)
        object.__setattr__(self, "steps", steps)

    @classmethod
    def uniform(cls, frequencies, n_steps: int = 4) -> "FrequencyPlan":
        """``n_steps`` equally spaced steps ``2 pi k / n_steps`` at every frequency (Hz)."""
        if int(n_steps) != n_steps or not 3 <= n_steps <= MAX_STEPS:
            raise InputError(f"FrequencyPlan.uniform: n_steps must be an integer in 3..{MAX_STEPS}, found {n_steps!r}")
        freqs = tuple(float(v) for v in np.atleast_1d(frequencies))
        step = tuple(2 * np.pi * k / int(n_steps) for k in range(int(n_steps)))
        return cls(freqs, tuple(step for _ in freqs))

    @property
    def n_samples(self) -> int:
        """Raw samples per frame: the sum of the step counts."""
        return sum(len(s) for s in self.steps)

    @property
    def wrap_lengths(self) -> np.ndarray:
        """(F,) metres: ``c / (2 f)``, the range each frequency's phase wraps at."""
        return C_LIGHT / (2 * np.asarray(self.frequencies))

    @property
    def unambiguous_range(self) -> float:
        """Metres: ``c / (2 gcd(f))`` with the frequencies rounded to 1 Hz (the combined wrap length)."""
        g = reduce(math.gcd, (int(round(v)) for v in self.frequencies))
        return C_LIGHT / (2 * g)

    def slices(self) -> list[slice]:
        """Where each frequency's samples sit in a raw stack."""
        out, k = [], 0
        for s in self.steps:
            out.append(slice(k, k + len(s)))
            k += len(s)
        return out

    def describe(self) -> str:
        """E.g. ``16/80/120 MHz x 3/3/3 steps``."""
        mhz = "/".join(f"{v / 1e6:g}" for v in self.frequencies)
        steps = "/".join(str(len(s)) for s in self.steps)
        return f"{mhz} MHz x {steps} steps"

    def to_dict(self) -> dict:
        return {"frequencies_hz": list(self.frequencies), "steps_rad": [list(s) for s in self.steps]}

    @classmethod
    def from_dict(cls, data: dict, *, where: str = "frequency plan") -> "FrequencyPlan":
        if not isinstance(data, dict) or "frequencies_hz" not in data or "steps_rad" not in data:
            raise InputError(f"{where}: expected an object with 'frequencies_hz' and 'steps_rad', found {shown(data)}")
        try:
            return cls(tuple(data["frequencies_hz"]), tuple(tuple(s) for s in data["steps_rad"]))
        except (TypeError, ValueError) as exc:
            raise InputError(f"{where}: {exc}") from None
