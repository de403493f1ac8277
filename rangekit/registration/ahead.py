"""Registration work done while the views arrive, so that little is left when the last one is in (issue 36).

A scan's streaming processor (:mod:`rangekit.app.scan.streaming`) knows, before any view is decoded, the prior
poses (the turntable's) and, once the first view is in, the voxel (:func:`rangekit.registration.turntable.swept_voxel`).
So as each view arrives it can do what :func:`rangekit.registration.multiview.register_views` would do first:
downsample the view to the two levels (``voxel`` and ``fine_voxel``, with normals), build the fine level's k-d
tree, refine each first-round candidate pair whose two views are both in and, on the turntable, measure the
overlap of each pair the joint refinement will consider and find its first iteration's correspondences (they
depend on the start poses, known before any view, the two views' fine levels and samples only: issue 51). The final ``register_views(..., ahead=...)`` takes a level only when
its voxel is the same and every view is in, and a pair's result only when its job is equal to its own and its
clouds are the very level clouds taken; everything else it computes. A pair's refinement depends only on its job
and its two clouds (:mod:`rangekit.registration.pair_refine`), so the poses are the same bits with or without
the work ahead.

Frames as in :mod:`rangekit.registration.multiview`: ``T_world_view`` with world = the first view's frame.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from scipy.spatial import cKDTree

from rangekit.geometry import invert_T
from rangekit.registration.joint import joint_samples, pair_matches
from rangekit.registration.multiview import (MultiViewOptions, first_view_world, pair_jobs, refinement_pairs)
from rangekit.registration.pair_refine import PairJob, PairMapper, mutual_overlap, refine_pair
from rangekit.surface.cloud import PointCloud, downsample_with_normals

__all__ = ["RegistrationAhead"]


class RegistrationAhead:
    """Each view's two levels and each first-round pair, made as the views arrive (module doc).

    ``init_T_world_view``: (n, 4, 4) the prior poses the final call is given; ``options``: the final call's, with
    ``voxel`` set (the coarse level; ``fine_voxel`` or a third of it the fine one). :meth:`add` each view's cloud
    (its own frame) as it comes, from one thread; then pass the object to ``register_views(..., ahead=...)``.
    """

    def __init__(self, init_T_world_view: np.ndarray, options: MultiViewOptions) -> None:
        if options.voxel is None:
            raise ValueError("RegistrationAhead needs options.voxel: the levels are made before every view is in")
        self.options = options
        self.n = len(init_T_world_view)
        self.voxel = float(options.voxel)
        self.fine = self.voxel / 3.0 if options.fine_voxel is None else float(options.fine_voxel)
        T = first_view_world(np.asarray(init_T_world_view, dtype=np.float64))
        pairs = refinement_pairs(options, prior=True)(T, True)
        self._jobs = {(job.i, job.j): job for job in pair_jobs(pairs, lambda i, j: invert_T(T[i]) @ T[j], self.voxel,
                                                                options, 0, True, None)}
        self._levels: dict[float, dict[int, PointCloud]] = {self.voxel: {}, self.fine: {}}
        self._refined: dict[tuple[int, int], tuple] = {}
        self._trees: dict[int, cKDTree] = {}            # each view's fine level's k-d tree
        # On the turntable the joint refinement starts from the prior's nearest turntable poses: its candidate
        # pairs and their overlaps on the fine level are known before the last view is in.
        self._joint: dict[tuple[int, int], np.ndarray] = {}
        self._T_joint: np.ndarray | None = None
        if options.turntable:
            from rangekit.registration.turntable import onto_turntable

            self._T_joint = T_joint = onto_turntable(T)
            self._joint = {(i, j): invert_T(T_joint[i]) @ T_joint[j]
                           for i, j in refinement_pairs(options, prior=True)(T_joint, True)}
        self._overlaps: dict[tuple[int, int], float] = {}
        # ... and so are its first iteration's correspondences: each view's samples (drawn in view order, as the
        # joint refinement draws them) matched in the other view of each overlapping pair, both ways.
        self._draw = np.random.default_rng(options.rng)
        self._samples: dict[int, tuple[np.ndarray, np.ndarray | None]] = {}
        self._matches: dict[tuple[int, int], tuple[np.ndarray, np.ndarray]] = {}
        self._reach = 2.5 * self.fine       # the joint refinement's max_distance (multiview: 2.5 fine voxels)
        self.taken = {"levels": 0, "pairs": 0, "overlaps": 0, "matches": 0}   # what the final registration took

    @property
    def views(self) -> list[int]:
        """The views added so far."""
        return sorted(self._levels[self.fine])

    def add(self, k: int, cloud: PointCloud) -> None:
        """View ``k``'s cloud (its own frame): its two levels, then every first-round pair it completes."""
        coarse = downsample_with_normals(cloud, self.voxel)
        fine = downsample_with_normals(cloud, self.fine)
        self._trees[k] = cKDTree(fine.points)
        self._levels[self.fine][k] = fine
        self._levels[self.voxel][k] = coarse
        level, fine_level = self._levels[self.voxel], self._levels[self.fine]
        for (i, j), job in self._jobs.items():
            if k in (i, j) and i in level and j in level and (i, j) not in self._refined:
                self._refined[i, j] = refine_pair(job, level[i], level[j])
        if self.options.joint_iterations > 0 and k == len(self._samples):   # drawn in view order only
            picks = joint_samples(self._draw, len(fine.points), self.options.joint_samples)
            self._samples[k] = (fine.points[picks], None if fine.normals is None else fine.normals[picks])
        for (i, j), T_i_j in self._joint.items():
            if k in (i, j) and i in fine_level and j in fine_level:
                self._overlaps[i, j] = mutual_overlap(fine_level[i], fine_level[j], self._trees[i], self._trees[j],
                                                      T_i_j, 2 * self.fine)
                if self._overlaps[i, j] >= self.options.min_overlap and i in self._samples and j in self._samples:
                    for a, b, T_a_b in ((i, j, T_i_j), (j, i, invert_T(self._T_joint[j]) @ self._T_joint[i])):
                        self._matches[a, b] = pair_matches(T_a_b, *self._samples[b], fine_level[a], self._trees[a],
                                                           self._reach)

    def level(self, voxel: float, n: int) -> list[PointCloud] | None:
        """Every view's cloud downsampled to ``voxel`` when that is one of the two levels and all ``n`` views
        are in, else None."""
        got = self._levels.get(voxel)
        if got is None or n != self.n or sorted(got) != list(range(n)):
            return None
        self.taken["levels"] += 1
        return [got[k] for k in range(n)]

    def trees(self, clouds: Sequence[PointCloud]) -> list[cKDTree] | None:
        """The k-d trees of ``clouds`` when they are this object's fine level (as :meth:`level` gave it), else
        None."""
        fine = self._levels[self.fine]
        if len(clouds) != self.n or any(fine.get(k) is not c for k, c in enumerate(clouds)):
            return None
        return [self._trees[k] for k in range(self.n)]

    def overlap(self, a: PointCloud, b: PointCloud, tree_a: cKDTree, tree_b: cKDTree, T_a_b: np.ndarray,
                radius: float) -> float:
        """:func:`~rangekit.registration.pair_refine.mutual_overlap`, taken from what was measured ahead when it
        is the same pair of fine-level clouds at the same pose and radius."""
        fine = self._levels[self.fine]
        ids = {id(c): k for k, c in fine.items()}
        i, j = ids.get(id(a)), ids.get(id(b))
        if i is not None and j is not None and fine[i] is a and fine[j] is b and (i, j) in self._overlaps \
                and radius == 2 * self.fine and np.array_equal(self._joint[i, j], T_a_b) \
                and tree_a is self._trees[i] and tree_b is self._trees[j]:
            self.taken["overlaps"] += 1
            return self._overlaps[i, j]
        return mutual_overlap(a, b, tree_a, tree_b, T_a_b, radius)

    def first_matches(self, i: int, j: int, T_i: np.ndarray, T_j: np.ndarray, cloud_i: PointCloud, tree_i: cKDTree,
                      samples_j: np.ndarray, max_distance: float) -> tuple[np.ndarray, np.ndarray] | None:
        """The joint refinement's first-iteration correspondences of directed pair (target ``i``, source ``j``)
        (:data:`rangekit.registration.joint.FirstMatches`), when found here for the same start poses, target cloud
        and tree (this object's fine level), source samples and ``max_distance``; else None."""
        found = self._matches.get((i, j))
        if found is None or max_distance != self._reach or cloud_i is not self._levels[self.fine].get(i) \
                or tree_i is not self._trees.get(i) or not np.array_equal(T_i, self._T_joint[i]) \
                or not np.array_equal(T_j, self._T_joint[j]) or not np.array_equal(samples_j, self._samples[j][0]):
            return None
        self.taken["matches"] += 1
        return found

    def mapper(self, fallback: PairMapper | None = None) -> PairMapper:
        """A :data:`~rangekit.registration.pair_refine.PairMapper` that gives a pair refined ahead when its job
        equals the one asked and its clouds are the level clouds handed out; the others through ``fallback``
        (None: one after another here)."""

        def map_pairs(jobs: Sequence[PairJob], clouds: Sequence[PointCloud]) -> list:
            level = self._levels.get(jobs[0].voxel, {}) if jobs else {}
            out: list = [None] * len(jobs)
            missing = []
            for n, job in enumerate(jobs):
                if (job.i, job.j) in self._refined and _same_job(self._jobs[job.i, job.j], job) \
                        and clouds[job.i] is level.get(job.i) and clouds[job.j] is level.get(job.j):
                    out[n] = self._refined[job.i, job.j]
                    self.taken["pairs"] += 1
                else:
                    missing.append(n)
            if missing:
                todo = [jobs[n] for n in missing]
                made = (fallback(todo, clouds) if fallback is not None else
                        [refine_pair(job, clouds[job.i], clouds[job.j]) for job in todo])
                for n, result in zip(missing, made):
                    out[n] = result
            return out

        return map_pairs


def _same_job(a: PairJob, b: PairJob) -> bool:
    """Whether two pair jobs ask for the same refinement (every field equal, the pose to the bit)."""
    return (a.i, a.j, a.voxel, a.icp, a.min_overlap, a.min_constraint, a.max_rmse, a.prior, a.names) \
        == (b.i, b.j, b.voxel, b.icp, b.min_overlap, b.min_constraint, b.max_rmse, b.prior, b.names) \
        and np.array_equal(a.T_i_j, b.T_i_j)
