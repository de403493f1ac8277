"""UVC webcams (``devices.camera.type`` "uvc"): camera (frames through OpenCV's V4L2 backend, the stale frames
flushed, device loss and reconnect), controls (the rig file's camera controls as V4L2 controls, verified by reading
them back), v4l2 (the kernel's ioctls, through linuxpy's structures). linuxpy is imported by the functions that
open a device node."""
