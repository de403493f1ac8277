"""The projector's response (gamma), as stored in the rig file: pattern value ``p`` in [0, 1] -> radiance.

The model (a projector shows ``p`` as relative radiance ``p ** gamma``) and what a camera sees of it are
explained in :mod:`rangekit.coded.response`, which fits it from grey levels and corrects phase shifting
for it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rangekit.errors import InputError, shown

__all__ = ["ProjectorResponse"]


@dataclass(frozen=True)
class ProjectorResponse:
    """How a projector turns pattern values into light: relative radiance ``p ** gamma``.

    ``gamma`` is dimensionless and > 0; 1 is a linear projector. Stored in the rig file as
    ``"projector_response": {"gamma": 2.2}``.
    """

    gamma: float = 1.0

    def __post_init__(self) -> None:
        g = self.gamma
        if isinstance(g, bool) or not isinstance(g, (int, float, np.floating, np.integer)) \
                or not math.isfinite(g) or g <= 0:
            raise InputError(f"projector response: gamma must be a finite number > 0 (1 = linear projector), "
                             f"found {shown(g)}")
        object.__setattr__(self, "gamma", float(g))

    @property
    def is_linear(self) -> bool:
        return self.gamma == 1.0

    def __call__(self, p: np.ndarray) -> np.ndarray:
        """Relative radiance of pattern values ``p`` in [0, 1] (clipped): ``p ** gamma``, same shape."""
        return np.clip(np.asarray(p, dtype=np.float64), 0.0, 1.0) ** self.gamma

    def to_dict(self) -> dict:
        return {"gamma": self.gamma}

    @classmethod
    def from_dict(cls, data: dict, *, where: str = "projector_response") -> "ProjectorResponse":
        """Inverse of :meth:`to_dict`. Errors read ``{where}: ...`` or ``{where}.gamma: ...``."""
        if not isinstance(data, dict):
            raise InputError(f"{where}: must be an object {{\"gamma\": number}} or null, found {shown(data)}")
        unknown = [k for k in data if k != "gamma"]
        if unknown:
            raise InputError(f"{where}: unknown field(s) {', '.join(map(repr, unknown))}; a projector response "
                             "has only 'gamma'")
        if "gamma" not in data:
            raise InputError(f"{where}: missing field 'gamma' (the exponent of the projector's response, "
                             "1 = linear; measure it with rangekit.calib.response.measure_response)")
        try:
            return cls(gamma=data["gamma"])
        except InputError:
            raise InputError(f"{where}.gamma: must be a finite number > 0 (1 = linear projector), found "
                             f"{shown(data['gamma'])}") from None
