"""Simulated devices that implement the device protocols: camera, projector, turntable, their shared clock,
and turntable and projector firmware over a pty or loopback."""
