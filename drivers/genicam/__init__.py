"""GenICam/GenTL machine-vision cameras (Basler, FLIR, Allied Vision, IDS, Daheng...) through harvesters: producer
(the GenTL producer's .cti found, checked and opened; a device chosen by serial number or user id), nodes (the node
map written and read back; what a device lacks named as its limit), frames (a buffer as an image: Mono8/10/12/16,
Bayer to grey, RGB), camera (the camera of a rig: open, capture with the buffers flushed, triggers, reconnect).
harvesters and genicam are imported by the functions that open a producer, never at module level."""
