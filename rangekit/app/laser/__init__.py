"""Laser-line jobs: laser-plane calibration (simulated and on devices), a capture's reconstruction, a
session processed into a mesh, and its report."""
