"""Registration of range scans: ICP, GPA, synchronisation, coarse alignment, multi-view (Fusiello ch. 14-15)."""

from rangekit._runtime.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
