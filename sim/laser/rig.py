"""The simulator's laser-line rig: the default rig plus two Ciclop-like red line lasers.

Geometry (world frame = turntable frame, z up, metres): the camera keeps :func:`default_rig`'s pose
(0.5 m from the point 6 cm above the table centre, 25 degrees above the table). That keeps the laser
captures' ground truth in the same frame, with the same camera, as the coded-light captures, and a
camera looking down on the table sees both the object and the line on the table top. Each laser's
emitter sits at the camera's height and distance from the turntable axis, turned by +-30 degrees about
the axis from the camera's direction (Ciclop: lasers beside the camera, aimed at the axis); its light
sheet is the vertical plane through the turntable axis and the emitter, so the line is where that
plane meets the object. The fan's centre ray points from the emitter at the table centre (see
:func:`rangekit.sim.laser.curve.fan_direction`); a 60 degree fan covers the table centre up to 0.26 m.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from rangekit.geometry import axis_angle_to_R
from rangekit.rig.lasers import LineLaser, laser_plane
from rangekit.rig.rig_file import Rig
from rangekit.sim.devices.sim_rig import default_rig

__all__ = ["ciclop_lasers", "laser_rig", "LASER_ANGLES_DEG"]

#: Where the two lasers stand, degrees about the turntable axis from the camera's direction.
LASER_ANGLES_DEG = (30.0, -30.0)


def ciclop_lasers(rig: Rig, *, angles_deg=LASER_ANGLES_DEG, line_width: float = 0.0008, power: float = 0.6,
                  channel: str = "red") -> tuple[LineLaser, ...]:
    """Line lasers beside ``rig``'s camera, turned by ``angles_deg`` about the turntable axis (the z axis
    of ``rig.T_world_table``); each plane holds the axis and its emitter. Switches 1, 2, ..."""
    T = rig.T_world_table if rig.T_world_table is not None else np.eye(4)
    axis, foot = T[:3, 2], T[:3, 3]
    cam = rig.camera.center
    lasers = []
    for i, a in enumerate(angles_deg):
        origin = foot + axis_angle_to_R(axis, math.radians(a)) @ (cam - foot)
        radial = origin - foot - axis * float(axis @ (origin - foot))
        plane = laser_plane(np.cross(axis, radial), foot, towards=cam)
        lasers.append(LineLaser(plane=plane, name=f"laser{i}", origin=origin, fan_angle=math.radians(60.0),
                                channel=channel, line_width=line_width, power=power, switch=i + 1))
    return tuple(lasers)


def laser_rig(rig: Rig | None = None, **options) -> Rig:
    """``rig`` (default :func:`default_rig`) with :func:`ciclop_lasers` (``options`` go to it)."""
    rig = rig if rig is not None else default_rig()
    return replace(rig, lasers=ciclop_lasers(rig, **options))
