"""Every view's first pose with no prior, multi-view registration's coarse stage: each view coarsely aligned with
its most similar views (:mod:`.graph`; every pair when asked), each alignment ICP-verified (:mod:`.align`'s seeds
in turn while the verified fit is refused), the accepted pairs synchronised (robustly), the graph widened until
they settle. Poses ``T_world_view`` with the first view's frame as world; edges ``T_i_j`` (view j into view i)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from rangekit.errors import RegistrationError
from rangekit.registration.coarse.align import CoarseOptions, coarse_align_seeds, compute_features
from rangekit.registration.coarse.graph import descriptor_distances, view_descriptor, widen_until_settled
from rangekit.registration.pair_refine import EdgeResult, check_dense, edge_result
from rangekit.registration.pairs import all_pairs
from rangekit.registration.sync import synchronise_accepted
from rangekit.registration.view_graph import EdgesDisagree, cut_off_message, edges_connect_views
from rangekit.surface.cloud import PointCloud

__all__ = ["CoarsePoses", "coarse_poses"]


@dataclass(frozen=True, eq=False)
class CoarsePoses:
    """The coarse stage's answer: ``T_world_view`` (n, 4, 4) synchronised poses, the ``edges`` it tried (accepted
    or refused, each with its reason) and ``label``: which pairs it tried ("all pairs", "k=4 most similar by FPFH
    histogram")."""

    T_world_view: np.ndarray
    edges: list[EdgeResult]
    label: str


def coarse_poses(clouds: Sequence[PointCloud], voxel: float, *, neighbours: int | None, min_overlap: float,
                 min_constraint: float, max_rmse: float, rng: int, names: Sequence[str] | None,
                 say: Callable[[str], None]) -> CoarsePoses:
    """The coarse poses of ``clouds`` (each downsampled to ``voxel`` metres, with normals).

    ``neighbours``: each view aligned with its k most similar first (widened as needed), None: every pair;
    ``min_overlap``, ``min_constraint``, ``max_rmse`` (metres): an alignment's acceptance
    (:func:`rangekit.registration.pair_refine.edge_result`); ``rng``: the features' and RANSAC's seed; ``names``:
    the views' names for errors; ``say`` gets one line. RegistrationError when a view has too few points for the
    voxel, no pair is accepted, or the views cannot be joined (:class:`EdgesDisagree` naming the views cut off).
    """
    n = len(clouds)
    copt = CoarseOptions(voxel=voxel, rng=rng)
    check_dense(clouds, range(n), voxel, names)
    feats = [compute_features(c, copt) for c in clouds]

    def align(i: int, j: int) -> EdgeResult:
        def edge(r) -> EdgeResult:
            return edge_result(i, j, r, r.fitness, min_overlap, min_constraint, max_rmse, prior=False)

        try:   # seeds in turn while the verified fit is refused (coarse.align.SEEDS)
            r = coarse_align_seeds(feats[j], feats[i], copt, lambda r: edge(r).accepted)
        except RegistrationError as exc:   # this pair only (e.g. no feature matches): a refused edge
            return EdgeResult(i, j, np.eye(4), np.inf, 0.0, False, str(exc).removeprefix("coarse alignment: "))
        return edge(r)

    def settle(edges: list) -> np.ndarray:
        edges_connect_views(n, edges, names)
        return synchronise_accepted(n, edges).T_world_view

    k = neighbours
    if k is None:
        edges, label = [align(i, j) for i, j in all_pairs(clouds)], "all pairs"
        T = settle(edges)
    else:
        dist = descriptor_distances(np.stack([view_descriptor(f.fpfh) for f in feats]))
        try:
            edges, T, k = widen_until_settled(dist, k, align, settle)
        except EdgesDisagree as cut:
            raise EdgesDisagree(cut_off_message(cut.views, names, voxel), cut.views) from None
        label = f"k={k} most similar by FPFH histogram"
    say(f"coarse alignment of {len(edges)} of {n * (n - 1) // 2} pairs ({label}, voxel "
        f"{voxel * 1e3:.2f} mm): {sum(e.accepted for e in edges)} accepted")
    return CoarsePoses(T, edges, label)
