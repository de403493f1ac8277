"""Acquisition: a crash-safe session captured view by view (turntable, lights, camera), its frames
rendered, encoded and written behind the capture."""
