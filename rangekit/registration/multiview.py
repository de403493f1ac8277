"""Registration of many scans into one frame (Fusiello ch. 14.3 and 15).

1. Initial poses: a prior (e.g. the turntable's axis and angles) or, with none, coarse alignment of
   every pair (FPFH + RANSAC, ICP-verified) followed by robust synchronisation of the accepted pairs.
2. Refinement rounds: with the current poses, find the candidate pairs (``options.pairs``, by default
   the nearest views in rotation when there is a prior, all pairs without) that overlap, register each pair by ICP
   starting from the current relative pose, accept an edge only if its inlier RMSE is small and its
   overlap large enough (ICP "fitness" alone accepts symmetric flips), and synchronise rotations and
   translations robustly over the accepted edges.

Poses: ``T_world_view`` maps a view's points into the world, which is the first view's frame.
Relative edges are ``T_i_j`` (view j into view i).
"""

from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field, replace
from typing import Callable, Protocol, Sequence

import numpy as np
from scipy.spatial import cKDTree

from rangekit._runtime.executor import worker_count
from rangekit._runtime.arguments import (check_bool, check_callable, check_instance, check_items, check_number,
                                         check_pose, check_text, refuse)
from rangekit.errors import RegistrationError
from rangekit.geometry import apply_T, invert_T
from rangekit.surface.cloud import PointCloud, bbox_diagonal, check_voxel, downsample_with_normals
from rangekit.surface.convert import as_cloud
from rangekit.registration.coarse.views import coarse_poses
from rangekit.registration.icp import IcpOptions
from rangekit.registration.joint import JointResult, refine_jointly
from rangekit.registration.overlap_estimate import overlapping_pairs
from rangekit.registration.pair_refine import EdgeResult, PairJob, PairMapper, mutual_overlap, pairwise_overlap, refine_pair
from rangekit.registration.pairs import (PairChooser, PairsTried, all_pairs, chooser_label, nearest_and_long_links,
                                         nearest_in_rotation)
from rangekit.registration.stability import MIN_CONSTRAINT, HeldMotions
from rangekit.registration.sync import SyncResult, synchronise_accepted
from rangekit.registration.view_graph import EdgesDisagree, cut_off_message, edges_connect_views
from rangekit._runtime.threads import one_blas_thread


class WorkAhead(Protocol):
    """What :func:`register_views` takes of work done before every view was in (implemented by
    :class:`rangekit.registration.ahead.RegistrationAhead`; a protocol here so that module may import this one)."""

    def level(self, voxel: float, n: int) -> list[PointCloud] | None: ...
    def mapper(self, fallback: PairMapper | None = None) -> PairMapper: ...
    def trees(self, clouds: Sequence[PointCloud]) -> list[cKDTree] | None: ...
    def overlap(self, a: PointCloud, b: PointCloud, tree_a: cKDTree, tree_b: cKDTree, T_a_b: np.ndarray,
                radius: float) -> float: ...
    def first_matches(self, i: int, j: int, T_i: np.ndarray, T_j: np.ndarray, cloud_i: PointCloud, tree_i: cKDTree,
                      samples_j: np.ndarray, max_distance: float) -> tuple[np.ndarray, np.ndarray] | None: ...


__all__ = ["MultiViewOptions", "EdgeResult", "MultiViewResult", "register_views", "pairwise_overlap",
           "first_view_world", "refinement_pairs", "pair_jobs", "WorkAhead", "JointResult", "refine_jointly", "overlap_rms"]


@dataclass(frozen=True)
class MultiViewOptions:
    """Settings; lengths in metres, ``None`` = derived from the data (voxel = bounding-box diagonal / 110)."""

    voxel: float | None = None           # coarse features and the first refinement round
    fine_voxel: float | None = None      # later rounds (default voxel / 3)
    min_overlap: float = 0.15            # fraction of a view's points within 2 voxels of the other
    max_rmse: float = 0.45               # accepted pairs: RMSE (2-voxel gate) below this many voxels
    max_coarse_rmse: float = 0.45        # coarse pairs: ICP-verified RMSE below this many voxels. Wrong
                                         # alignments (e.g. front/back flips) can keep 0.3-0.6 overlap but
                                         # not a low RMSE: on the bunny, right <= 0.36, wrong >= 0.64 voxel
    rounds: int = 1
    min_constraint: float = MIN_CONSTRAINT  # a pair whose overlap leaves a motion with a smaller eigenvalue
                                         # ratio free (rangekit.registration.stability) is ambiguous: with
                                         # no prior it is not an edge; with one, the prior is kept along
                                         # that motion and the edge is flagged
    joint_iterations: int = 60           # joint multi-view refinement after synchronisation (0: none)
    joint_tolerance: float = 1e-6        # metres: stop when no pose moves a point by more (1 um, as the
                                         # pairwise ICP: 2 iterations instead of 4 on the 12-view scan, the
                                         # same poses within 0.0001 deg, 1/10 of the points' 13 um noise)
    joint_samples: int = 20000           # points per view in the joint refinement (at most all fine points);
                                         # 20k: the 50k poses to 1e-3 deg on the 12-view scan (docs/benchmarks.md)
    pairs: PairChooser | None = None     # refinement candidates (rangekit.registration.pairs), None: the
                                         # 4 nearest in rotation (+ long links and the most overlapping with
                                         # no prior; all pairs with a non-turntable prior); see _register_views
    coarse_neighbours: int | None = 4    # no prior: coarse alignment of each view with its k most similar
                                         # (registration.coarse.graph), widened as needed; None = all pairs
    icp: IcpOptions = field(default_factory=lambda: IcpOptions(method="point_to_plane", kernel="huber",
                                                               max_iterations=60, tolerance=1e-6, max_samples=5000))
                                         # pairwise runs only start the joint refinement: 1 um and 5k
                                         # points suffice (the joint step ends at the same poses)
    turntable: bool = False              # with a prior: the views are on a turntable, and the joint
                                         # refinement keeps them rotations about one common axis (its
                                         # 4 parameters and each view's angle: rangekit.registration.turntable)
    rng: int = 0

    def __post_init__(self) -> None:
        for name in ("voxel", "fine_voxel"):
            check_number(name, getattr(self, name), lo=0, lo_open=True, unit="metres", optional=True)
        check_number("min_overlap", self.min_overlap, lo=0, hi=1)
        for name in ("max_rmse", "max_coarse_rmse"):
            check_number(name, getattr(self, name), lo=0, lo_open=True, unit="voxels")
        check_number("rounds", self.rounds, lo=1, integer=True)
        check_number("min_constraint", self.min_constraint, lo=0)
        check_number("joint_iterations", self.joint_iterations, lo=0, integer=True)
        check_number("joint_tolerance", self.joint_tolerance, lo=0, unit="metres")
        check_number("joint_samples", self.joint_samples, lo=1, integer=True)
        check_callable("pairs", self.pairs)
        check_number("coarse_neighbours", self.coarse_neighbours, lo=1, integer=True, optional=True)
        check_instance("icp", self.icp, IcpOptions, "an IcpOptions")
        check_bool("turntable", self.turntable)
        check_number("rng", self.rng, lo=0, integer=True)


@dataclass(frozen=True, eq=False)
class MultiViewResult:
    T_world_view: np.ndarray          # (n, 4, 4)
    edges: tuple[EdgeResult, ...]     # last round's pairs
    sync: SyncResult                  # last synchronisation (edge residuals, inliers)
    rmse: float                       # RMS point-to-plane residual of the final poses, metres; lower is better
    pairs: PairsTried | None = None   # how many pairs each stage tried
    converged: bool = True            # the joint refinement stopped by its tolerance, not its iteration limit

    def __repr__(self) -> str:
        acc = sum(e.accepted for e in self.edges)
        return f"MultiViewResult({len(self.T_world_view)} views, {acc}/{len(self.edges)} edges, rmse={self.rmse * 1e3:.3f} mm)"


def _prepare(clouds: Sequence[PointCloud], voxel: float, given: list[PointCloud] | None = None) -> list[PointCloud]:
    """Each cloud downsampled to ``voxel`` with normals (``given``: already so, by :class:`RegistrationAhead`)."""
    for k, c in enumerate(clouds):  # every view's own faults first, then those of the voxel
        pts = np.asarray(c.points)
        if len(pts) < 50:
            raise RegistrationError(f"view {k}: {len(pts)} points; a scan needs at least 50 to register")
        if not np.all(np.isfinite(pts)):
            raise RegistrationError(f"view {k}: has NaN or infinite points; drop them first")
    if given is not None:
        return given
    with ThreadPoolExecutor(max_workers=worker_count(), thread_name_prefix="rangekit-voxels") as pool:   # in order
        return list(pool.map(lambda c: downsample_with_normals(c, voxel), clouds))


OVERLAP_NEIGHBOURS = 8   # no prior: each view's most overlapping views (estimated) added to the candidates


def _joint_holds(n: int, pairs: list, edges: list[EdgeResult], holds: dict, T: np.ndarray) -> dict:
    """``{view: [HeldMotions in world]}`` for the views whose every joint pair is an accepted edge that
    kept the prior along some motions (a pair with no such edge constrains its views: no hold)."""
    accepted = {(e.i, e.j) for e in edges if e.accepted}
    out: dict[int, list] = {}
    free_of: dict[int, bool] = {}
    for i, j in pairs:
        h = holds.get((i, j)) if (i, j) in accepted else None
        for k in (i, j):
            free_of[k] = free_of.get(k, True) and h is not None
            if h is not None:
                R, t = T[i][:3, :3], T[i][:3, 3]   # view i's frame into world
                out.setdefault(k, []).append(HeldMotions(np.hstack([h.motions[:, :3] @ R.T, h.motions[:, 3:] @ R.T]),
                                                         R @ h.centre + t, h.length))
    return {k: v for k, v in out.items() if free_of.get(k)}


def register_views(clouds: Sequence[PointCloud], *, init_T_world_view: np.ndarray | None = None,
                   options: MultiViewOptions = MultiViewOptions(), progress: Callable[[str], None] | None = None,
                   names: Sequence[str] | None = None, map_pairs: PairMapper | None = None,
                   ahead: WorkAhead | None = None) -> MultiViewResult:
    """Register ``clouds`` (each in its own frame) into the first cloud's frame.

    Parameters
    ----------
    clouds : PointClouds in metres (or any cloud :func:`rangekit.surface.convert.as_cloud` takes); normals are
        used when present (else estimated).
    init_T_world_view : (n, 4, 4), optional prior poses; None runs coarse alignment of every pair.
    options : MultiViewOptions.
    progress : called with one line per stage.
    names : the views' names for error messages (e.g. file names).
    map_pairs : runs each refinement round's pair jobs (:data:`rangekit.registration.pair_refine.PairMapper`);
        None: one after another here. The Dask batch maps them onto its workers (the same bits).
    ahead : the work a scan did while its views arrived (:class:`rangekit.registration.ahead.RegistrationAhead`):
        each view's downsampled levels and first-round pairs, taken where they are exactly what this call would
        compute (the same voxels, prior and pair jobs), so the result is the same bits with or without it.

    Ambiguous pairs (a rigid motion left free, rangekit.registration.stability): with no prior not edges (a
    view reached only through them: RegistrationError naming the views and the motion); with a prior, ICP
    solves the constrained motions, keeps the prior along the free ones and the edge's ``reason`` says so.
    """
    clouds = check_items("clouds", clouds, "a list of clouds", min_items=1)
    init_T_world_view = check_pose("init_T_world_view", init_T_world_view, count=len(clouds), optional=True)
    check_instance("options", options, MultiViewOptions, "a MultiViewOptions")
    check_callable("progress", progress)
    for k, name in enumerate(check_items("names", names, f"{len(clouds)} names, one per cloud", optional=True) or ()):
        check_text(f"names[{k}]", name, what="a view's name")
    if names is not None and len(list(names)) != len(clouds):
        refuse("names", names, f"{len(clouds)} names, one per cloud")
    check_callable("map_pairs", map_pairs)
    if ahead is not None and not callable(getattr(ahead, "level", None)):
        refuse("ahead", ahead, "a RegistrationAhead or None", wrong_type=True)
    with one_blas_thread():    # thin (n, 6) and (N, 3) products: rangekit._runtime.threads
        return _register_views([as_cloud(c, f"register_views clouds[{i}]") for i, c in enumerate(clouds)],
                               init_T_world_view, options, progress, names, map_pairs, ahead)


def first_view_world(T_world_view: np.ndarray) -> np.ndarray:
    """(n, 4, 4) the poses with the first view's frame as the world."""
    return np.einsum("ij,njk->nik", invert_T(T_world_view[0]), T_world_view)


def refinement_pairs(options: MultiViewOptions, prior: bool) -> PairChooser:
    """The chooser of the refinement's candidate pairs: ``options.pairs``, else on the turntable the neighbours
    in angle, with no prior the neighbours in rotation, long links (and the most overlapping, estimated), with
    any other prior every pair (it may be degrees off)."""
    return options.pairs or (nearest_and_long_links() if not prior else
                             nearest_in_rotation() if options.turntable else all_pairs)


def pair_jobs(pairs: Sequence[tuple[int, int]], start: Callable[[int, int], np.ndarray], v: float,
              options: MultiViewOptions, rnd: int, prior: bool, names: Sequence[str] | None) -> list[PairJob]:
    """One :class:`PairJob` per pair of a refinement round ``rnd`` on the level of voxel ``v`` (metres), each from
    ``start(i, j)`` (its T_i_j). A wide gate on a coarser level first (the prior may be degrees off), then a
    2-voxel gate, so the final RMSE measures the overlap only and is comparable with the coarse stage's."""
    icp_opt = replace(options.icp, max_distance=2.0 * v, voxel_sizes=(2.0 * v,), rng=options.rng + rnd)
    return [PairJob(i, j, start(i, j), v, icp_opt, options.min_overlap, options.min_constraint, options.max_rmse * v,
                    prior, None if names is None else (names[i], names[j])) for i, j in pairs]


def _register_views(clouds, init_T_world_view, options, progress, names, map_pairs, ahead) -> MultiViewResult:
    """:func:`register_views` on checked arguments: the levels, the coarse poses (no prior), the refinement
    rounds, the joint refinement."""
    say = progress or (lambda msg: None)
    n = len(clouds)
    if n < 2:
        raise RegistrationError(f"multi-view registration needs at least 2 scans, found {n}")
    diag = bbox_diagonal(clouds)
    voxel = diag / 110.0 if options.voxel is None else check_voxel(options.voxel, diag, what="voxel")
    fine = voxel / 3.0 if options.fine_voxel is None else check_voxel(options.fine_voxel, diag, what="fine_voxel")
    coarse_clouds = _prepare(clouds, voxel, None if ahead is None else ahead.level(voxel, n))
    fine_clouds = _prepare(clouds, fine, None if ahead is None else ahead.level(fine, n))
    if ahead is not None:
        map_pairs = ahead.mapper(map_pairs)
    prior = init_T_world_view is not None
    steps = _Refinement(n, options, prior, names, map_pairs, say, (coarse_clouds, voxel), (fine_clouds, fine))
    n_coarse, coarse_label = 0, ""
    if not prior:
        coarse = coarse_poses(coarse_clouds, voxel, neighbours=options.coarse_neighbours,
                              min_overlap=options.min_overlap, min_constraint=options.min_constraint,
                              max_rmse=options.max_coarse_rmse * voxel, rng=options.rng, names=names, say=say)
        T, n_coarse, coarse_label = coarse.T_world_view, len(coarse.edges), coarse.label
        steps.seen |= {(e.i, e.j) for e in coarse.edges}
    else:
        T = first_view_world(init_T_world_view)   # (n, 4, 4), checked by register_views
    T_prior = T.copy()
    edges: list[EdgeResult] = []
    holds: dict = {}
    sync = None
    for rnd in range(options.rounds):
        T, edges, holds, sync = steps.run_round(T, rnd)
    acc = [e for e in edges if e.accepted]
    rmse, n_joint, converged = float(np.mean([e.rmse for e in acc])), 0, True
    if options.joint_iterations > 0:
        T, rmse, n_joint, converged = steps.joint(T, T_prior, edges, holds, ahead)
    label = chooser_label(steps.choose) + (f" + {OVERLAP_NEIGHBOURS} most overlapping (estimated)" if steps.estimate
                                           else "")
    tried = PairsTried(n, len(steps.seen), n_coarse, steps.n_candidates, steps.n_refined, n_joint, label, coarse_label)
    say(tried.summary())
    return MultiViewResult(T, tuple(edges), sync, rmse, tried, converged)


class _Refinement:
    """The refinement's steps over one registration's views and their state. ``coarse`` and ``fine``: each
    (the views downsampled with normals, that voxel in metres), the first round's level and the later rounds' and
    joint refinement's; ``prior``: the poses came from a prior (else from the coarse stage); ``map_pairs``: runs a
    round's pair jobs (None: two at a time here). State: ``seen``, every pair tried; ``n_candidates`` and
    ``n_refined``, the last round's candidate pairs and pairs measured; the fine level's k-d trees, built once."""

    def __init__(self, n: int, options: MultiViewOptions, prior: bool, names: Sequence[str] | None,
                 map_pairs: PairMapper | None, say: Callable[[str], None], coarse: tuple[list, float],
                 fine: tuple[list, float]) -> None:
        self.n, self.options, self.prior, self.names, self.map_pairs, self.say = n, options, prior, names, map_pairs, say
        self.coarse, self.fine = coarse, fine
        # On the turntable the neighbours in angle; with no prior the neighbours in rotation, long links and the
        # most overlapping (O(n k)). Any other prior may be degrees off: every pair (options.pairs bounds it).
        self.choose = refinement_pairs(options, prior)
        self.estimate = options.pairs is None and not prior   # + the most overlapping, as a prior's all pairs would
        self.seen: set = set()
        self.n_candidates = self.n_refined = 0
        self.fine_trees: list | None = None

    def candidates(self, T: np.ndarray, level: list, v: float) -> list:
        """The candidate pairs at poses ``T`` (n, 4, 4) on ``level`` (voxel ``v``, metres)."""
        pairs = self.choose(T, self.prior)
        if self.estimate:
            pairs = sorted(set(pairs) | set(overlapping_pairs([apply_T(T[k], level[k].points) for k in range(self.n)],
                                                              2 * v, OVERLAP_NEIGHBOURS, self.options.min_overlap)))
        return pairs

    def refine(self, pairs: list, start: Callable[[int, int], np.ndarray], level: list, trees: list, v: float,
               rnd: int) -> tuple[list, dict]:
        """ICP of each pair from ``start(i, j)`` (its T_i_j) on ``level`` with voxel ``v``: (edges, holds)."""
        jobs = pair_jobs(pairs, start, v, self.options, rnd, self.prior, self.names)
        if self.map_pairs is None:   # pairs side by side (their k-d tree queries release the GIL), taken in order
            with ThreadPoolExecutor(max_workers=worker_count(), thread_name_prefix="rangekit-pairs") as pool:
                refined = list(pool.map(lambda job: refine_pair(job, level[job.i], level[job.j], trees[job.i],
                                                                trees[job.j]), jobs))
        else:
            refined = self.map_pairs(jobs, level)
        out_edges, out_holds = [], {}
        for job, out in zip(jobs, refined):
            if out is not None:
                out_edges.append(out[0])
                if out[1] is not None:
                    out_holds[job.i, job.j] = out[1]
        return out_edges, out_holds

    def run_round(self, T: np.ndarray, rnd: int) -> tuple[np.ndarray, list, dict, SyncResult]:
        """Refinement round ``rnd`` from poses ``T``: its candidate pairs refined, measured again where their
        edges disagree, synchronised: (poses, edges, holds, the synchronisation)."""
        level, v = self.coarse if rnd == 0 else self.fine
        trees = [cKDTree(c.points) for c in level]
        candidates = self.candidates(T, level, v)
        self.seen |= set(candidates)
        self.n_candidates = len(candidates)
        edges, holds = self.refine(candidates, lambda i, j: invert_T(T[i]) @ T[j], level, trees, v, rnd)
        edges_connect_views(self.n, edges, self.names)
        edges, holds, sync = self.remeasure(edges, holds, T, rnd)
        self.n_refined = len(edges)
        acc = [e for e in edges if e.accepted]
        self.say(f"round {rnd + 1}: {len(acc)}/{len(edges)} overlapping pairs accepted, mean rmse "
                 f"{np.mean([e.rmse for e in acc]) * 1e3:.3f} mm")
        return sync.T_world_view, edges, holds, sync

    def remeasure(self, edges: list, holds: dict, T_start: np.ndarray, rnd: int) -> tuple[list, dict, SyncResult]:
        """The round's edges synchronised; while some views' edges disagree, every pair of theirs measured again
        on the fine level (on the Stanford dragon a 15k-point view's 3 mm edges disagreed by 1.5 deg, its 1 mm
        edges agree), each from its accepted edge or the round's start ``T_start``. EdgesDisagree when the same
        views disagree again."""
        fine_clouds, fine = self.fine
        widened: set = set()
        while True:
            try:
                return edges, holds, synchronise_accepted(self.n, edges)
            except EdgesDisagree as cut:
                new = [c for c in cut.views if c not in widened]
                if not new:
                    raise EdgesDisagree(cut_off_message(cut.views, self.names, self.coarse[1]), cut.views) from None
                widened |= set(new)
                pairs = sorted({(min(c, k), max(c, k)) for c in new for k in range(self.n) if k != c})
                kept = {(e.i, e.j): e.T_i_j for e in edges if e.accepted}
                if self.fine_trees is None:
                    self.fine_trees = [cKDTree(c.points) for c in fine_clouds]
                more, more_holds = self.refine(
                    pairs, lambda i, j: kept.get((i, j), invert_T(T_start[i]) @ T_start[j]), fine_clouds,
                    self.fine_trees, fine, rnd)
                redo = set(pairs)
                edges = [e for e in edges if (e.i, e.j) not in redo] + more
                holds = {k: h for k, h in holds.items() if k not in redo} | more_holds
                self.seen |= redo
                self.say(f"views {new}: edges disagree; {len(pairs)} pairs measured again at {fine * 1e3:.2f} mm, "
                         f"{sum(e.accepted for e in more)} accepted")

    def joint(self, T: np.ndarray, T_prior: np.ndarray, edges: list, holds: dict,
              ahead: WorkAhead | None) -> tuple[np.ndarray, float, int, bool]:
        """The joint refinement of every view on the fine level from the synchronised poses ``T`` (on the turntable
        from the prior ``T_prior`` put onto one axis, moving the axis and the angles only): (poses, rmse in metres,
        the pairs it used, converged)."""
        fine_clouds, fine = self.fine
        options, n = self.options, self.n
        basis = None
        if options.turntable and self.prior:
            # The turntable's own poses start the joint refinement, which then moves the axis and the
            # angles only: they are in the family already, and on sparse clouds (8k points a view) the
            # pairwise results synchronised to poses 1.4 deg and 3.6 mm off, where no pair overlapped.
            from rangekit.registration.turntable import onto_turntable, turntable_basis

            T, basis = onto_turntable(T_prior), turntable_basis
        # Pairs by overlap at the synchronised poses (not by which pairwise runs passed), so the same data
        # gives the same problem whatever the starting poses were.
        trees = (self.fine_trees or (ahead is not None and ahead.trees(fine_clouds))
                 or [cKDTree(c.points) for c in fine_clouds])
        joint_candidates = self.candidates(T, fine_clouds, fine)
        self.seen |= set(joint_candidates)
        overlap = mutual_overlap if ahead is None else ahead.overlap
        pairs = [(i, j) for i, j in joint_candidates
                 if overlap(fine_clouds[i], fine_clouds[j], trees[i], trees[j], invert_T(T[i]) @ T[j],
                            2 * fine) >= options.min_overlap]
        joint = refine_jointly(fine_clouds, T, pairs, max_distance=2.5 * fine, iterations=options.joint_iterations,
                               samples=options.joint_samples, tolerance=options.joint_tolerance, rng=options.rng,
                               hold=_joint_holds(n, pairs, edges, holds, T), basis=basis, trees=trees,
                               first=None if ahead is None else ahead.first_matches)
        self.say(f"joint refinement of {n} views over {len(pairs)} pairs: rmse {joint.rmse * 1e3:.4f} mm, "
                 f"{joint.n_iterations} iterations{'' if joint.converged else ' (not converged)'}")
        return joint.T_world_view, joint.rmse, len(pairs), bool(joint.converged)


def overlap_rms(clouds: Sequence[PointCloud], T_world_view: np.ndarray, *, radius: float = 0.001) -> float:
    """RMS distance between overlapping scans: for every ordered pair, each point of one scan to its
    nearest neighbour in the other if closer than ``radius`` (metres). A measure of how well poses fit
    the data (used to compare with a reference alignment such as Stanford's bun.conf)."""
    world = [apply_T(T, np.asarray(c.points)) for c, T in zip(clouds, T_world_view)]
    trees = [cKDTree(w) for w in world]
    sq, count = 0.0, 0
    for i in range(len(world)):
        for j in range(len(world)):
            if i == j:
                continue
            d, _ = trees[i].query(world[j], k=1, distance_upper_bound=radius, workers=1)
            d = d[np.isfinite(d)]
            sq += float(np.sum(d ** 2))
            count += d.size
    return float(np.sqrt(sq / max(count, 1)))
