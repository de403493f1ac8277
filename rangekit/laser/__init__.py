"""Laser-line scanning (Fusiello 13.2.4): a sheet of light swept over the object by the turntable; each lit
camera pixel triangulated against the laser's plane (ray-plane, eq. 13.7).

Modules: ``peaks`` (subpixel line peaks in a laser-on minus laser-off image), ``triangulate`` (peak rays
against a laser plane), ``plane_fit`` (robust plane fit), ``plane_calib`` (laser-plane calibration from board
poses and the turntable plate), ``sequence`` (the frames a laser scan takes at each turntable step),
``sheet_stereo`` (laser-sheet stereo: the line seen by a calibrated camera pair, no laser plane; not re-exported
here, it loads :mod:`rangekit.stereo`: import it as ``rangekit.laser.sheet_stereo``).
"""

from rangekit._runtime.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
