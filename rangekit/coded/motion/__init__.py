"""Motion during a coded-light capture (issue 38 item 3): :mod:`rangekit.coded.motion.check` (the check of binary
codes, pixel by pixel), :mod:`rangekit.coded.motion.detect` (whether a view moved, on a pair of lines in 16: what the
scan and the processing refuse a view by), :mod:`rangekit.coded.motion._kernels` (their compiled loops)."""

from rangekit._runtime.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
