"""One refinement of one view pair, the unit that :func:`rangekit.registration.multiview.register_views` maps
over a round's candidate pairs: serially by default, or as one Dask task a pair (``map_pairs``,
:mod:`rangekit.app.batch.sessions`). A pair's result depends only on its two downsampled clouds and its
:class:`PairJob`, so the two give the same bits.

Frames: ``T_i_j`` maps view j's points into view i's frame; ``target`` is view i, ``source`` view j.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable, Sequence

import numpy as np
from scipy.spatial import cKDTree

from rangekit.errors import RegistrationError
from rangekit.geometry import apply_T, invert_T, rotation_angle
from rangekit.surface.cloud import PointCloud
from rangekit.registration.icp import IcpOptions, icp
from rangekit.registration.stability import HeldMotions, PoseConstraint

__all__ = ["EdgeResult", "PairJob", "PairMapper", "MIN_VOXELS", "OVERLAP_SAMPLES", "check_dense", "edge_result",
           "mutual_overlap", "pairwise_overlap", "refine_pair"]

MIN_VOXELS = 30   # points a view must keep after voxel downsampling: fewer cannot fix 6 degrees of freedom
                  # with any margin (and FPFH needs neighbours)
OVERLAP_SAMPLES = 5000   # points of a view that estimate its overlap (every k-th point): a fraction within
                         # about 1% (binomial), for a threshold of 0.15


@dataclass(frozen=True, eq=False)
class EdgeResult:
    """One pairwise registration in the view graph."""

    i: int
    j: int
    T_i_j: np.ndarray        # (4, 4) maps view j into view i
    rmse: float              # ICP inlier RMSE, metres
    overlap: float           # fraction of view j's points with a partner in view i
    accepted: bool
    reason: str = ""
    unconstrained: str = ""  # the motions the overlap leaves free ('' if none), see rangekit.registration.stability
    constraint: PoseConstraint | None = None

    def __repr__(self) -> str:
        return (f"EdgeResult({self.i}-{self.j}, rmse={self.rmse * 1e3:.3f} mm, overlap={self.overlap:.2f}, "
                f"accepted={self.accepted}{', ' + self.reason if self.reason else ''})")


@dataclass(frozen=True, eq=False)
class PairJob:
    """Everything but the clouds that one pair's refinement needs (small: pickled to a Dask worker)."""

    i: int
    j: int
    T_i_j: np.ndarray            # (4, 4) the current relative pose
    voxel: float                 # metres: this round's voxel (overlap radius and ICP gate 2 voxels)
    icp: IcpOptions
    min_overlap: float
    min_constraint: float
    max_rmse: float              # metres: accepted edges have an RMSE below it
    prior: bool                  # the poses come from a prior (an ambiguous pair keeps it along free motions)
    names: tuple[str, str] | None = None   # the views' names, for error messages


#: ``map_pairs(jobs, clouds)`` -> ``[refine_pair(job, clouds[job.i], clouds[job.j]) for job in jobs]``, in order.
PairMapper = Callable[[Sequence[PairJob], Sequence[PointCloud]], list]


def check_dense(clouds: Sequence[PointCloud], views: Sequence[int], voxel: float,
                names: Sequence[str] | None) -> None:
    """RegistrationError if one of ``views`` kept fewer than MIN_VOXELS points after downsampling (checked
    where the points are used, so scans that do not overlap at all say that instead)."""
    for k in views:
        if len(clouds[k]) < MIN_VOXELS:
            raise RegistrationError(f"view {k}{f' ({names[k]})' if names is not None else ''}: {len(clouds[k])} "
                                    f"points after downsampling to {voxel * 1e3:.3g} mm voxels, expected at least "
                                    f"{MIN_VOXELS}; use a smaller voxel (--voxel-mm) or a denser scan")


def pairwise_overlap(src: PointCloud, tgt_tree: cKDTree, T_tgt_src: np.ndarray, radius: float) -> float:
    """Fraction of ``src`` points (at most about OVERLAP_SAMPLES of them, evenly strided) that land within
    ``radius`` of the target after ``T_tgt_src``."""
    pts = src.points[::max(1, len(src.points) // OVERLAP_SAMPLES)]
    d, _ = tgt_tree.query(apply_T(T_tgt_src, pts), k=1, distance_upper_bound=radius, workers=1)
    return float(np.mean(np.isfinite(d)))


def mutual_overlap(a: PointCloud, b: PointCloud, tree_a: cKDTree, tree_b: cKDTree, T_a_b: np.ndarray,
                   radius: float) -> float:
    """The larger of the two directed overlaps of views a and b (b's points in a, a's points in b)."""
    return max(pairwise_overlap(b, tree_a, T_a_b, radius), pairwise_overlap(a, tree_b, invert_T(T_a_b), radius))


def edge_result(i: int, j: int, r, overlap: float, min_overlap: float, min_constraint: float, max_rmse: float,
                prior: bool, note: str = "") -> EdgeResult:
    """Accept or refuse the registration ``r`` of view j into view i: RMSE below ``max_rmse`` (metres),
    overlap at least ``min_overlap``, and an overlap that fixes every motion, unless a prior holds
    the free ones (then the edge is accepted and its reason says the prior was kept)."""
    free = r.constraint.describe(min_constraint) if r.constraint is not None else ""
    if r.rmse >= max_rmse:
        reason = f"rmse {r.rmse * 1e3:.3f} mm > {max_rmse * 1e3:.3f}"
    elif overlap < min_overlap:
        reason = f"overlap {overlap:.2f}"
    elif free:
        reason = f"prior kept along: {free}" if prior else f"ambiguous: {free} unconstrained"
    else:
        reason = ""
    ok = not reason or (prior and free and reason.startswith("prior"))
    return EdgeResult(i, j, r.T_target_source, r.rmse, overlap, bool(ok), reason + note, free, r.constraint)


def refine_pair(job: PairJob, target: PointCloud, source: PointCloud, target_tree: cKDTree | None = None,
                source_tree: cKDTree | None = None) -> tuple[EdgeResult, HeldMotions | None] | None:
    """ICP of view j (``source``) onto view i (``target``) from ``job.T_i_j``: ``(edge, held)``, or None when
    the views overlap less than ``job.min_overlap`` there. ``held``: the motions kept at the prior (an
    ambiguous pair with a prior: ICP wandered along them and was run again holding them), else None.
    The k-d trees of the clouds are built here unless given (the serial caller builds each view's once)."""
    v = job.voxel
    tree_i = cKDTree(target.points) if target_tree is None else target_tree
    tree_j = cKDTree(source.points) if source_tree is None else source_tree
    if mutual_overlap(target, source, tree_i, tree_j, job.T_i_j, 2 * v) < job.min_overlap:
        return None
    check_dense({job.i: target, job.j: source}, (job.i, job.j), v,
                None if job.names is None else {job.i: job.names[0], job.j: job.names[1]})
    r = icp(source, target, init_T_target_source=job.T_i_j, options=job.icp)
    held = None
    if job.prior and r.constraint is not None and r.constraint.ratio < job.min_constraint:
        held = r.constraint.held(job.min_constraint)
        r = replace(icp(source, target, init_T_target_source=job.T_i_j, options=job.icp, hold=held),
                    constraint=r.constraint)
    ov = pairwise_overlap(source, tree_i, r.T_target_source, 2 * v)
    moved = np.degrees(rotation_angle(r.T_target_source[:3, :3] @ job.T_i_j[:3, :3].T))
    return (edge_result(job.i, job.j, r, ov, job.min_overlap, job.min_constraint, job.max_rmse, job.prior,
                        note=f" (moved {moved:.1f} deg)" if moved > 5 else ""), held)
