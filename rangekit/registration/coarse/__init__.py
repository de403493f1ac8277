"""Coarse alignment with no initial guess: one pair of scans (:mod:`.align`: FPFH features, RANSAC, ICP) and which
pairs of a view graph to try it on (:mod:`.graph`: view descriptors, similar pairs, the graph widened until it
settles); every view's first pose from them (:mod:`.views`, imported from there: it needs the pairs' refinement)."""

from rangekit._runtime.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
