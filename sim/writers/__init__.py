"""Simulated captures written as folders a real rig records: coded-light captures, turntable scans and
calibration sessions."""
