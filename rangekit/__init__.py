"""rangekit: active 3D scanning, from the rig's captures to one watertight mesh.

Import what you need from its modules (``rangekit.camera``, ``rangekit.geometry``, ``rangekit.sim``...);
importing the package itself is fast and loads no heavy dependency.
"""

__version__ = "0.1.0"
