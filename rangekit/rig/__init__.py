"""The rig: the rig file (cameras, projector, turntable, lasers, capture settings) and its checks, the
device protocols the drivers and the simulator implement, camera controls and the projector's response."""
