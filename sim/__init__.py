"""Simulated hardware with exact ground truth: scenes, ray casting, image formation, devices.

``from rangekit.sim import SimRig, default_scene`` gives a projector-camera-turntable rig that produces
the same captures as the hardware, plus the truth (depth, points, normals, projector coordinates). The names
below load on first use (rangekit._runtime.lazy, as every rangekit package re-exports).
"""

from rangekit._runtime.lazy import lazy_exports

_MODULE_OF = {
    **dict.fromkeys(("SimCamera", "SimProjector", "SimRig", "SimTurntable", "default_rig"), "devices.sim_rig"),
    **dict.fromkeys(("BUILTIN_OBJECTS", "load_scene_object", "make_object"), "scene.objects"),
    "SceneObject": "scene.scene_object",
    **dict.fromkeys(("ViewGeometry", "WorldMesh", "cast_view"), "scene.raycast"),
    **dict.fromkeys(("ImagingModel", "ViewRenderer"), "imaging.render"),
    **dict.fromkeys(("Scene", "default_scene"), "scene.scene"),
    **dict.fromkeys(("LIGHT_STAGE_MODEL", "LightStageCapture", "light_stage_camera", "light_stage_lights",
                     "light_stage_scene", "render_light_stage"), "sensors.lightstage"),
    **dict.fromkeys(("StereoCapture", "render_stereo", "speckle_pattern", "stereo_rig", "stereo_scene"),
                    "sensors.stereo"),
    **dict.fromkeys(("ToFCapture", "ToFSensor", "render_pulsed", "render_tof", "tof_camera", "tof_scene"),
                    "sensors.tof"),
}
__all__ = list(_MODULE_OF)
__getattr__, __dir__ = lazy_exports(__name__, _MODULE_OF, __all__)
