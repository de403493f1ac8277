"""Photometric stereo: normals and albedo from images under known or unknown lights, then depth.

Fusiello ch. 13.4. A Lambertian pixel with albedo-scaled normal ``g = albedo * n`` seen under a light
``s`` has intensity ``b = max(g . s, 0)``. Stacking ``f`` lights gives ``B = X S`` with ``B`` (p, f),
``X`` (p, 3) and ``S`` (3, f); least squares recovers ``X`` when ``S`` is known (calibrated), and a
rank-3 factorisation recovers it up to a 3x3 ambiguity when not (uncalibrated).

Frames and units: the OpenCV camera frame (x right, y down, z forward). Normals are unit vectors that
face the camera (``n_z < 0``); lights are unit vectors from the surface towards the light (so a light
on the camera's side has ``s_z < 0``). Depth ``Z`` grows away from the camera; an orthographic surface
``Z(x, y)`` has normal ``(Z_x, Z_y, -1) / norm``. Pixels are ``(u, v) = (column, row)``.

Everything per pixel is vectorised: pixels are processed in chunks of batched 3x3 normal equations,
never in a Python loop over pixels.
"""

from rangekit._runtime.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
