"""Registration of a multi-pass turntable scan: the object turned over between passes (issue 21).

Within a pass the views are turntable rotations, registered from the pass's prior
(:func:`~rangekit.registration.multiview.register_views` with ``turntable=True``). Between passes nothing
is known: the object was turned over by hand. So:

1. each pass is registered on its own, world = its first view's frame;
2. each later pass is aligned to the first with **no prior**: its views (at the fine voxel, kept for
   step 3) merged at their poses and downsampled again, FPFH + RANSAC
   (:func:`~rangekit.registration.coarse.coarse_align`; up to three seeds, until one ICP-verified fit
   passes the RMSE and fitness gates), then point-to-plane ICP on the merged clouds at the fine voxel;
3. one joint refinement (:func:`~rangekit.registration.joint.refine_jointly`) of every view over the pairs
   of :func:`pass_pairs`: each view's 2 nearest neighbours in its own pass and the 2 views of other passes
   that overlap it most at the poses found (an occupancy estimate, no ICP), so the pairs are linear in
   the views. The joint step is the plain 6-dof one: a pass is a turntable family about its own axis in
   the first view's frame, which the one-axis basis (:mod:`rangekit.registration.turntable`) cannot hold.

Poses ``T_world_view`` (4, 4), world = the first view of the first pass; metres, radians.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable, Sequence

import numpy as np
from scipy import sparse

from rangekit.errors import RegistrationError
from rangekit.geometry import apply_T, rotation_angle
from rangekit.registration.coarse import CoarseOptions, coarse_align, compute_features
from rangekit.registration.icp import IcpOptions, icp
from rangekit.registration.joint import refine_jointly
from rangekit.registration.multiview import EdgeResult, MultiViewOptions, MultiViewResult, register_views
from rangekit.registration.pairs import nearest_in_rotation
from rangekit.surface.cloud import PointCloud, bbox_diagonal, estimate_normals, merge_clouds, voxel_downsample

__all__ = ["PassesResult", "register_passes", "pass_pairs", "CROSS_NEIGHBOURS"]

#: Views of other passes paired with each view in the joint refinement (the most overlapping ones), and views
#: of its own pass (the nearest in rotation): the passes' own registrations already used 4 (pairs.py).
CROSS_NEIGHBOURS = 2
SAME_NEIGHBOURS = 2
#: Points per view in the joint refinement over all passes: the passes' own joint refinements (20k) fixed
#: their views already; this one mainly fixes the passes to each other, with every view in several pairs.
JOINT_SAMPLES = 10000
#: Seeds of the RANSAC between two passes' merged clouds, tried in turn until one fit passes the gates.
COARSE_SEEDS = 3


@dataclass(frozen=True, eq=False)
class PassesResult:
    """A multi-pass registration: ``T_world_view`` (n, 4, 4), world = view 0; ``edges`` the passes' own view
    graphs (global view indices) then one edge per later pass to the first (``i``, ``j`` = the passes'
    first views, ``T_i_j`` the passes' relative pose, ``reason`` how it was found); ``sync`` the residuals
    of the passes' accepted edges in order; ``rmse`` the joint refinement's, metres."""

    T_world_view: np.ndarray
    edges: tuple[EdgeResult, ...]
    sync: object
    rmse: float
    passes: tuple[MultiViewResult, ...]
    T_first_pass: np.ndarray          # (passes, 4, 4) each pass's world (its first view) in the first's
    n_pairs: int                      # pairs of the joint refinement


@dataclass(frozen=True)
class _Residuals:
    edge_rotation_error: np.ndarray
    edge_translation_error: np.ndarray


def _keys(points: np.ndarray, normals: np.ndarray | None, cell: float) -> np.ndarray:
    """Voxel cells of ``cell`` metres with the normal's dominant signed axis (6 bins), as int64 keys."""
    q = np.floor(points / cell).astype(np.int64)
    q -= q.min(axis=0) if len(q) else 0
    b = np.zeros(len(points), np.int64) if normals is None else (
        np.argmax(np.abs(normals), axis=1) * 2 + (normals[np.arange(len(normals)), np.argmax(np.abs(normals), axis=1)]
                                                  > 0))
    return ((q[:, 0] * 2_000_003 + q[:, 1]) * 2_000_003 + q[:, 2]) * 6 + b


def pass_pairs(clouds: Sequence[PointCloud], view_pass: Sequence[int], *, cell: float,
               k_same: int = SAME_NEIGHBOURS, k_cross: int = CROSS_NEIGHBOURS,
               min_overlap: float = 0.05) -> Callable[[np.ndarray, bool], list]:
    """A pair chooser (:mod:`rangekit.registration.pairs`) for a multi-pass scan: each view with its
    ``k_same`` nearest views in rotation of its own pass, and with the ``k_cross`` views of other passes
    sharing most occupied cells (``cell`` metres, same facing) at the given poses, when they share at least
    ``min_overlap`` of the smaller view's cells. The cells of all views are counted in one sparse product."""
    vp = np.asarray(view_pass)
    same_choose = nearest_in_rotation(k_same)

    def choose(T_world_view: np.ndarray, prior: bool = False) -> list[tuple[int, int]]:
        out = set()
        for p in np.unique(vp):
            idx = np.flatnonzero(vp == p)
            if len(idx) > 1:
                out.update((int(idx[a]), int(idx[b])) for a, b in same_choose(T_world_view[idx], prior))
        keys = []
        for c, T in zip(clouds, T_world_view):
            step = max(1, len(c.points) // 4000)
            n = None if c.normals is None else c.normals[::step] @ T[:3, :3].T
            keys.append(np.unique(_keys(apply_T(T, c.points[::step]), n, cell)))
        allk, col = np.unique(np.concatenate(keys), return_inverse=True)
        row = np.repeat(np.arange(len(keys)), [len(k) for k in keys])
        A = sparse.csr_matrix((np.ones(len(row)), (row, col)), shape=(len(keys), len(allk)))
        shared = (A @ A.T).toarray()
        sizes = np.diag(shared).copy()
        frac = shared / np.maximum(1.0, np.minimum(sizes[:, None], sizes[None, :]))
        frac[vp[:, None] == vp[None, :]] = 0.0
        for i in range(len(keys)):
            for j in np.argsort(-frac[i], kind="stable")[:k_cross]:
                if frac[i, j] >= min_overlap:
                    out.add((min(i, int(j)), max(i, int(j))))
        return sorted(out)

    return choose


def _prepare(clouds: Sequence[PointCloud], voxel: float) -> list[PointCloud]:
    out = []
    for c in clouds:
        p, n = voxel_downsample(np.asarray(c.points), voxel, normals=c.normals)
        out.append(PointCloud(p, normals=n if n is not None else estimate_normals(p, k=20)))
    return out


def _align_pass(source: PointCloud, target: PointCloud, voxel: float, fine: float, p: int,
                options: MultiViewOptions) -> tuple[np.ndarray, EdgeResult]:
    """``T_first_p`` (pass p's merged cloud into the first pass's; both merged from the views' clouds at
    the fine voxel) with no prior, and its edge record."""
    copt = CoarseOptions(voxel=voxel, rng=options.rng)
    coarse_s, coarse_t = (compute_features(c, copt) for c in (source, target))   # features once for every seed
    best = None
    for seed in range(COARSE_SEEDS):
        try:
            r = coarse_align(coarse_s, coarse_t, replace(copt, rng=options.rng + seed))
        except RegistrationError:
            continue
        ok = r.rmse < options.max_coarse_rmse * voxel and r.fitness >= options.min_overlap
        if best is None or (ok, r.fitness) > (best[0], best[1].fitness):
            best = (ok, r)
        if ok:      # verified: the later seeds only run when this one failed
            break
    if best is None or not best[0]:
        found = "no fit" if best is None else f"ICP RMSE {best[1].rmse * 1e3:.3f} mm, fitness {best[1].fitness:.2f}"
        raise RegistrationError(f"pass {p + 1}: no alignment to pass 1 found without a prior (expected an ICP-verified "
                                f"RMSE below {options.max_coarse_rmse * voxel * 1e3:.3f} mm and a fitness of at least "
                                f"{options.min_overlap:.2f}, found {found}); the passes "
                                "may not overlap: turn the object less far over or scan more views")
    r = icp(source, target, init_T_target_source=best[1].T_target_source,
            options=IcpOptions(method="point_to_plane", kernel="huber", max_distance=2 * fine, max_iterations=60,
                               tolerance=1e-7, max_samples=20000))
    edge = EdgeResult(-1, -1, r.T_target_source, r.rmse, r.fitness, True,
                      f"pass {p + 1} to pass 1, no prior: {best[1].reason}; fine ICP rmse {r.rmse * 1e3:.3f} mm")
    return r.T_target_source, edge


def register_passes(clouds: Sequence[PointCloud], view_pass: Sequence[int], priors: Sequence[np.ndarray | None], *,
                    options: MultiViewOptions = MultiViewOptions(turntable=True),
                    progress: Callable[[str], None] | None = None,
                    names: Sequence[str] | None = None) -> PassesResult:
    """Register a multi-pass scan (see the module docstring).

    ``clouds``: every view in its own frame; ``view_pass`` (n,) each view's pass (0, 1, ...; every pass
    non-empty, in order); ``priors``: per pass the (m_p, 4, 4) prior of its views (the turntable's), or
    None (coarse alignment within the pass too). ``options``: those of each pass's registration; the joint
    step uses its ``joint_*`` settings. Raises RegistrationError when a pass cannot be aligned to the first.
    """
    say = progress or (lambda msg: None)
    vp = np.asarray(view_pass, dtype=np.int64)
    n_passes = int(vp.max()) + 1
    groups = [np.flatnonzero(vp == p) for p in range(n_passes)]
    if len(vp) != len(clouds) or any(len(g) < 2 for g in groups) or len(priors) != n_passes:
        raise RegistrationError(f"register_passes: expected {len(clouds)} view passes, every pass with 2 or more "
                                f"views and one prior per pass; found passes of {[len(g) for g in groups]} views "
                                f"and {len(priors)} priors")
    results, edges, rot, tr = [], [], [], []
    for p, g in enumerate(groups):
        say(f"pass {p + 1} of {n_passes}: registering its {len(g)} views")
        res = register_views([clouds[k] for k in g], init_T_world_view=priors[p], progress=progress,
                             options=options if priors[p] is not None else replace(options, turntable=False),
                             names=None if names is None else [names[k] for k in g])
        results.append(res)
        edges += [replace(e, i=int(g[e.i]), j=int(g[e.j])) for e in res.edges]
        rot.append(res.sync.edge_rotation_error)
        tr.append(res.sync.edge_translation_error)
    diag = bbox_diagonal(clouds)
    voxel = diag / 110.0 if options.voxel is None else options.voxel
    fine = voxel / 3.0 if options.fine_voxel is None else options.fine_voxel
    fine_clouds = _prepare(clouds, fine)
    merged = [_prepare([merge_clouds([fine_clouds[k] for k in g], r.T_world_view)], fine)[0]
              for g, r in zip(groups, results)]
    T_first = [np.eye(4)]
    for p in range(1, n_passes):
        T, edge = _align_pass(merged[p], merged[0], voxel, fine, p, options)
        T_first.append(T)
        edges.append(replace(edge, i=int(groups[0][0]), j=int(groups[p][0])))
        say(f"pass {p + 1} aligned to pass 1 without a prior: turned {np.degrees(rotation_angle(T[:3, :3])):.1f} deg; "
            f"{edge.reason}")
    T = np.zeros((len(clouds), 4, 4))
    for g, r, Tp in zip(groups, results, T_first):
        T[g] = np.einsum("ij,njk->nik", Tp, r.T_world_view)
    pairs = pass_pairs(fine_clouds, vp, cell=4 * fine, k_same=SAME_NEIGHBOURS)(T, True)
    if options.joint_iterations > 0:
        joint = refine_jointly(fine_clouds, T, pairs, max_distance=2.5 * fine, iterations=options.joint_iterations,
                               samples=min(JOINT_SAMPLES, options.joint_samples), tolerance=options.joint_tolerance,
                               rng=options.rng)
        T, rmse = joint.T_world_view, joint.rmse
        n_cross = sum(vp[i] != vp[j] for i, j in pairs)
        say(f"joint refinement of {len(clouds)} views over {len(pairs)} pairs ({n_cross} across passes): rmse "
            f"{joint.rmse * 1e3:.4f} mm, {joint.n_iterations} iterations"
            f"{'' if joint.converged else ' (not converged)'}")
    else:
        rmse = float(np.mean([r.rmse for r in results]))
    return PassesResult(T, tuple(edges), _Residuals(np.concatenate(rot), np.concatenate(tr)), float(rmse),
                        tuple(results), np.stack(T_first), len(pairs))
