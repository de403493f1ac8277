"""Calibration procedures for camera, projector and turntable. See issue 7."""
