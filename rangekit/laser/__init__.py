"""Laser-line scanning (Fusiello 13.2.4): a sheet of light swept over the object by the turntable; each lit
camera pixel triangulated against the laser's plane (ray-plane, eq. 13.7).

Modules: ``peaks`` (subpixel line peaks in a laser-on minus laser-off image), ``triangulate`` (peak rays
against a laser plane), ``plane_fit`` (robust plane fit), ``plane_calib`` (laser-plane calibration from board
poses and the turntable plate).
"""

__all__: list[str] = []
