"""Simulated hardware with exact ground truth: scenes, ray casting, image formation, devices.

``from rangekit.sim import SimRig, default_scene`` gives a projector-camera-turntable rig that produces
the same captures as the hardware, plus the truth (depth, points, normals, projector coordinates).
"""

from rangekit.sim.devices.sim_rig import SimCamera, SimProjector, SimRig, SimTurntable, default_rig
from rangekit.sim.scene.objects import BUILTIN_OBJECTS, load_mesh, make_object
from rangekit.sim.scene.scene_object import SceneObject
from rangekit.sim.scene.raycast import ViewGeometry, WorldMesh, cast_view
from rangekit.sim.imaging.render import ImagingModel, ViewRenderer
from rangekit.sim.scene.scene import Scene, default_scene

__all__ = [
    "SimCamera", "SimProjector", "SimRig", "SimTurntable", "default_rig",
    "BUILTIN_OBJECTS", "SceneObject", "load_mesh", "make_object",
    "ViewGeometry", "WorldMesh", "cast_view",
    "ImagingModel", "ViewRenderer",
    "Scene", "default_scene",
]

from rangekit.sim.sensors.lightstage import (LIGHT_STAGE_MODEL, LightStageCapture, light_stage_camera, light_stage_lights,
                                     light_stage_scene, render_light_stage)

__all__ += ["LIGHT_STAGE_MODEL", "LightStageCapture", "light_stage_camera", "light_stage_lights",
            "light_stage_scene", "render_light_stage"]

from rangekit.sim.sensors.stereo import StereoCapture, render_stereo, speckle_pattern, stereo_rig, stereo_scene
from rangekit.sim.sensors.tof import ToFCapture, ToFSensor, render_pulsed, render_tof, tof_camera, tof_scene

__all__ += ["StereoCapture", "render_stereo", "speckle_pattern", "stereo_rig", "stereo_scene",
            "ToFCapture", "ToFSensor", "render_pulsed", "render_tof", "tof_camera", "tof_scene"]
