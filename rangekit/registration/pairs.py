"""Which pairs of views multi-view registration tries (the view graph's candidate edges).

A chooser is a function ``(T_world_view, prior) -> [(i, j), ...]`` (``i < j``): given the current poses
((n, 4, 4), world = the first view's frame) and whether they came from a prior, the pairs worth an
overlap test. Registration then keeps only the candidates whose overlap is real (``min_overlap``), so a
chooser only bounds the work: all pairs cost O(n^2) overlap tests, ICP runs and joint-refinement terms,
nearest neighbours O(n k).

- :func:`all_pairs`: every pair (no prior: the coarse poses may be anywhere).
- :func:`nearest_in_rotation`: each view with the ``k`` views whose poses differ least in rotation (on a
  turntable: the neighbours in angle, k / 2 on either side).
- :func:`long_links`: a handful of far pairs (each of a few evenly spread views with the view nearest to
  90 deg away in rotation), so drift cannot accumulate around a ring of nearest neighbours.
- :func:`nearest_and_long_links`: both, O(n k) pairs in all (the default).
- :func:`default_pairs`: nearest 4 in rotation with a (turntable) prior; without one, at the poses of the
  coarse alignment's synchronisation, nearest 4 plus 4 long links.

A chooser may carry a ``label`` attribute (e.g. ``"k=4 nearest + 4 long links"``) that
``register_views`` prints with the number of pairs tried.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from rangekit.errors import InputError

__all__ = ["PairChooser", "all_pairs", "nearest_in_rotation", "long_links", "nearest_and_long_links",
           "default_pairs", "chooser_label", "PairsTried", "PRIOR_NEIGHBOURS", "LONG_LINKS", "LONG_LINK_ANGLE"]

PairChooser = Callable[[np.ndarray, bool], list]

#: Neighbours per view with a prior: on the 12-view turntable (30 deg apart) the views 30 and 60 deg
#: away, 24 pairs instead of 66, at the same pose error (docs/benchmarks.md, registration).
PRIOR_NEIGHBOURS = 4
#: Long links per graph and the rotation they aim at: a handful, O(1) pairs whatever n (a link whose views
#: do not overlap is dropped by the overlap test like any candidate).
LONG_LINKS = 4
LONG_LINK_ANGLE = np.pi / 2


def all_pairs(T_world_view: np.ndarray, prior: bool = False) -> list[tuple[int, int]]:
    """Every pair ``(i, j)``, ``i < j``, of the ``len(T_world_view)`` views."""
    n = len(T_world_view)
    return [(i, j) for i in range(n) for j in range(i + 1, n)]


all_pairs.label = "all pairs"


def chooser_label(choose: PairChooser) -> str:
    """The chooser's ``label`` attribute, else its name."""
    return getattr(choose, "label", None) or getattr(choose, "__name__", "custom chooser")


def _rotation_gaps(T_world_view: np.ndarray) -> np.ndarray:
    """(n, n) angle (radians) of the relative rotation between every two poses."""
    R = np.asarray(T_world_view, dtype=np.float64)[:, :3, :3]
    tr = np.einsum("iab,jab->ij", R, R)   # trace(R_i^T R_j)
    return np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0))


def nearest_in_rotation(k: int = PRIOR_NEIGHBOURS) -> PairChooser:
    """A chooser pairing each view with the ``k`` views (k >= 1) nearest to it in rotation (ties by
    index); the union over the views, so a view may get more than ``k`` pairs."""
    if not (isinstance(k, (int, np.integer)) and k >= 1):
        raise InputError(f"nearest_in_rotation: k must be an integer >= 1, found {k!r}")

    def choose(T_world_view: np.ndarray, prior: bool = False) -> list[tuple[int, int]]:
        gaps = _rotation_gaps(T_world_view)
        n = len(gaps)
        np.fill_diagonal(gaps, np.inf)
        out = set()
        for i in range(n):
            for j in np.argsort(gaps[i], kind="stable")[:min(k, n - 1)].tolist():
                out.add((min(i, j), max(i, j)))
        return sorted(out)

    choose.label = f"k={k} nearest"
    return choose


def long_links(T_world_view: np.ndarray, count: int = LONG_LINKS,
               angle: float = LONG_LINK_ANGLE) -> list[tuple[int, int]]:
    """``count`` far pairs ``(i, j)``, ``i < j``: views ``i`` evenly spread over the indices, each with the
    view whose rotation differs from it closest to ``angle`` (radians; ties by index) among those not yet
    linked to it; O(count * n log n) work."""
    gaps = _rotation_gaps(T_world_view)
    n = len(gaps)
    out: set = set()
    if n < 3 or count < 1:
        return []
    for a in np.unique(np.linspace(0, n, min(count, n), endpoint=False).astype(int)).tolist():
        miss = np.abs(gaps[a] - angle)
        miss[a] = np.inf
        for b in np.argsort(miss, kind="stable")[:-1].tolist():   # the nearest to angle not yet linked
            if (min(a, b), max(a, b)) not in out:
                out.add((min(a, b), max(a, b)))
                break
    return sorted(out)


def nearest_and_long_links(k: int = PRIOR_NEIGHBOURS, links: int = LONG_LINKS,
                           angle: float = LONG_LINK_ANGLE) -> PairChooser:
    """A chooser: :func:`nearest_in_rotation` (``k``) plus :func:`long_links` (``links`` pairs aiming at
    ``angle`` radians); at most ``n k + links`` pairs."""
    if not (isinstance(links, (int, np.integer)) and links >= 0):
        raise InputError(f"nearest_and_long_links: links must be an integer >= 0, found {links!r}")
    nearest = nearest_in_rotation(k)

    def choose(T_world_view: np.ndarray, prior: bool = False) -> list[tuple[int, int]]:
        near = nearest(T_world_view, prior)
        return sorted(set(near) | set(long_links(T_world_view, links, angle)))

    choose.label = f"k={k} nearest + {links} long links"
    return choose


def default_pairs(T_world_view: np.ndarray, prior: bool = False) -> list[tuple[int, int]]:
    """The :data:`PRIOR_NEIGHBOURS` nearest views in rotation, plus :data:`LONG_LINKS` long links without
    a prior. With a turntable prior the joint refinement keeps the views on one axis, so drift cannot
    accumulate, and long links only add risk: on the step gauge (tests/registration/test_turntable_registration.py)
    its 90 deg pairs slide and the robust synchronisation then refused 9 of 28 edges."""
    return (nearest_in_rotation() if prior else nearest_and_long_links())(T_world_view, prior)


default_pairs.label = f"k={PRIOR_NEIGHBOURS} nearest (+ {LONG_LINKS} long links without a prior)"


@dataclass(frozen=True)
class PairsTried:
    """How much of the view graph registration tried (counts of view pairs)."""

    views: int
    tried: int            # distinct pairs that any stage looked at (coarse alignment or overlap test)
    coarse: int           # coarse alignments (FPFH + RANSAC + ICP); 0 with a prior
    candidates: int       # refinement candidates from the chooser (each gets an overlap test)
    refined: int          # of them, pairs registered by ICP (they overlapped)
    joint: int            # pairs in the joint refinement
    label: str            # the chooser, e.g. "k=4 nearest + 4 long links"
    coarse_label: str = ""  # how the coarse pairs were chosen ('' with a prior)

    @property
    def all_pairs(self) -> int:
        return self.views * (self.views - 1) // 2

    def summary(self) -> str:
        """One line, e.g. ``view graph: 28 of 66 pairs tried (refined: 22 of 28 candidates, k=4 nearest + 4
        long links; joint: 22)``."""
        coarse = f"coarse: {self.coarse} ({self.coarse_label}); " if self.coarse else ""
        return (f"view graph: {self.tried:,} of {self.all_pairs:,} pairs tried ({coarse}refined: {self.refined} of "
                f"{self.candidates} candidates, {self.label}; joint: {self.joint})")
