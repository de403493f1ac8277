"""The names of ``rangekit.sim``, each loaded from its module on first use (rangekit._runtime.lazy.attach_stub)."""

from .devices.sim_rig import (SimCamera as SimCamera, SimProjector as SimProjector, SimRig as SimRig,
    SimTurntable as SimTurntable, default_rig as default_rig)
from .scene.objects import (BUILTIN_OBJECTS as BUILTIN_OBJECTS, load_scene_object as load_scene_object,
    make_object as make_object)
from .scene.scene_object import SceneObject as SceneObject
from .scene.raycast import ViewGeometry as ViewGeometry, WorldMesh as WorldMesh, cast_view as cast_view
from .imaging.render import ImagingModel as ImagingModel, ViewRenderer as ViewRenderer
from .scene.scene import Scene as Scene, default_scene as default_scene
from .sensors.lightstage import (LIGHT_STAGE_MODEL as LIGHT_STAGE_MODEL, LightStageCapture as LightStageCapture,
    light_stage_camera as light_stage_camera, light_stage_lights as light_stage_lights,
    light_stage_scene as light_stage_scene, render_light_stage as render_light_stage)
from .sensors.stereo import (StereoCapture as StereoCapture, render_stereo as render_stereo,
    speckle_pattern as speckle_pattern, stereo_rig as stereo_rig, stereo_scene as stereo_scene)
from .sensors.tof import (ToFCapture as ToFCapture, ToFSensor as ToFSensor, render_pulsed as render_pulsed,
    render_tof as render_tof, tof_camera as tof_camera, tof_scene as tof_scene)
