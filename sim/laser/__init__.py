"""The simulated laser-line scanner: its rig, the lit curves, frames, capture folders, calibration boards and
the peaks' truth."""
