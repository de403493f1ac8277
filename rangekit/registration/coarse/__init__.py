"""Coarse alignment with no initial guess: one pair of scans (:mod:`.align`: FPFH features, RANSAC, ICP) and which
pairs of a view graph to try it on (:mod:`.graph`: view descriptors, similar pairs, the graph widened until it
settles); every view's first pose from them (:mod:`.views`, imported from there: it needs the pairs' refinement)."""

from rangekit.registration.coarse.align import (CoarseOptions, Features, coarse_align, coarse_align_seeds,
                                                compute_features)

__all__ = ["CoarseOptions", "Features", "coarse_align", "coarse_align_seeds", "compute_features"]
