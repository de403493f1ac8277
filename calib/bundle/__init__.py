"""The bundle adjustment of a camera-projector calibration: problem (`BundleProblem`: its parameters, observations,
residuals and grouped finite-difference Jacobian), reduced (the adjustment posed for the reduced system), schur (the
reduced-system solver)."""
