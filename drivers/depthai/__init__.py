"""Luxonis depthai (OAK) cameras: camera (the colour or mono camera of a structured-light rig), controls (its
exposure, ISO, focus, white balance), stereo (its stereo depth). depthai itself is imported lazily, by the
function that opens a device (rangekit.drivers.discovery finds and opens it)."""
