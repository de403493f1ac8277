"""Image formation: what the simulated camera records for a projected image, its sensor, and the compiled
inner loops."""
