"""Rig files in and out: ``rangekit rig import`` of OpenCV, depthai and Horus calibrations, and a rig file's
text with matrices on one line."""
