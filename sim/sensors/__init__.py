"""Other simulated sensors: time of flight, the active-stereo pair, the photometric light stage."""
