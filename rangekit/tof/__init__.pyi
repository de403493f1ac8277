"""The names of ``rangekit.tof``, each loaded from its module on first use (rangekit._runtime.lazy.attach_stub)."""

from .plan import C_LIGHT as C_LIGHT, FrequencyPlan as FrequencyPlan
from .phase import (PhaseMaps as PhaseMaps, UnwrapResult as UnwrapResult,
    phase_amplitude_offset as phase_amplitude_offset, phase_to_range as phase_to_range, range_sigma as range_sigma,
    unwrap_ranges as unwrap_ranges)
from .decode import ToFResult as ToFResult, decode_cw as decode_cw
from .pulsed import (pulsed_range as pulsed_range, round_trip_problem as round_trip_problem,
    MAX_ROUND_TRIP_S as MAX_ROUND_TRIP_S)
from .range_maps import (flying_pixels as flying_pixels, partial_pixels as partial_pixels,
    range_to_depth as range_to_depth, range_to_points as range_to_points)
