"""Metrology: least-squares fits of geometric standards and the VDI/VDE 2634 part 2 figures.

Modules: ``sphere_fit`` (Gaussian sphere fit, Gauss-Newton from an algebraic start), ``plane_fit``
(Gaussian plane fit), ``vdi2634`` (probing errors PF and PS, sphere-spacing error SD, flatness F).
"""

from rangekit._runtime.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
