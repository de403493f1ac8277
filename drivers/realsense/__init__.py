"""Intel RealSense cameras through pyrealsense2: device (the SDK boundary: a camera by serial number or a recording,
an option set and read back, a stream's intrinsics), camera (the infrared imager, emitter off, as the
structured-light camera), depth (the depth stream, emitter on, as an active-stereo range sensor). pyrealsense2
itself is imported by the functions that open a device."""
