"""Laser-line scanning (Fusiello 13.2.4): a sheet of light swept over the object by the turntable; each lit
camera pixel triangulated against the laser's plane (ray-plane, eq. 13.7).

Modules: ``peaks`` (subpixel line peaks in a laser-on minus laser-off image), ``triangulate`` (peak rays
against a laser plane), ``plane_fit`` (robust plane fit), ``plane_calib`` (laser-plane calibration from board
poses and the turntable plate), ``sequence`` (the frames a laser scan takes at each turntable step),
``sheet_stereo`` (laser-sheet stereo: the line seen by a calibrated camera pair, no laser plane; not re-exported
here, it loads :mod:`rangekit.stereo`: import it as ``rangekit.laser.sheet_stereo``).
"""

from rangekit.laser.peaks import LinePeaks, detect_peaks, require_peaks
from rangekit.laser.plane_calib import (board_view, calibrate_laser_plane, calibrated_laser, plane_errors, plate_view,
                                        report_lines)
from rangekit.laser.plane_fit import PlaneFit, fit_plane
from rangekit.laser.sequence import LaserSequence
from rangekit.laser.triangulate import LaserPoints, to_turntable_frame, triangulate_peaks

__all__ = ["LinePeaks", "detect_peaks", "require_peaks", "triangulate_peaks", "to_turntable_frame", "LaserPoints",
           "fit_plane", "PlaneFit", "board_view", "plate_view", "calibrate_laser_plane", "calibrated_laser",
           "plane_errors", "report_lines", "LaserSequence"]
