"""The names of ``rangekit.laser``, each loaded from its module on first use (rangekit._runtime.lazy.attach_stub)."""

from .peaks import LinePeaks as LinePeaks, detect_peaks as detect_peaks, require_peaks as require_peaks
from .triangulate import (triangulate_peaks as triangulate_peaks, to_turntable_frame as to_turntable_frame,
    LaserPoints as LaserPoints)
from .plane_fit import fit_plane as fit_plane, PlaneFit as PlaneFit
from .plane_calib import (board_view as board_view, plate_view as plate_view,
    calibrate_laser_plane as calibrate_laser_plane, calibrated_laser as calibrated_laser,
    plane_errors as plane_errors, report_lines as report_lines)
from .sequence import LaserSequence as LaserSequence
