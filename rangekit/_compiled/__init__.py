"""Compiled kernels of the core (numba, cached on disk), each the same operations as the numpy formula it stands
for: lens (the OpenCV lens model: distortion, its Jacobian, the undistortion's Newton passes) and colour
(``colourise``'s one pass). Imported by the function that needs them, so that ``import rangekit`` loads no numba.
Nothing is imported here."""
