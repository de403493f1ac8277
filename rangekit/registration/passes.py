"""Registration of a multi-pass turntable scan: the object turned over between passes (issue 21).

Within a pass the views are turntable rotations, registered from the pass's prior
(:func:`~rangekit.registration.multiview.register_views` with ``turntable=True``). Between passes nothing
is known: the object was turned over by hand. So:

1. each pass is registered on its own, world = its first view's frame (the pass's own joint refinement on
   its turntable family leaves its views about 0.001 deg apart from the truth);
2. each later pass is aligned to the first with **no prior**, as one rigid block: its views (at the fine
   voxel) merged at their poses and downsampled again, FPFH + RANSAC
   (:func:`~rangekit.registration.coarse.coarse_align`; up to three seeds, until one ICP-verified fit
   passes the RMSE and fitness gates), then point-to-plane ICP on the merged clouds at the fine voxel.
   That one 6-dof motion per later pass is all that is solved between passes: a joint 6-dof refinement of
   every view over same- and cross-pass pairs afterwards cost a third of the registration at 72 views and
   left the poses further from the truth (0.0072 deg, against 0.0010 deg for the blocks; docs/passes.md).

Poses ``T_world_view`` (4, 4), world = the first view of the first pass; metres, radians.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable, Sequence

import numpy as np

from rangekit.errors import RegistrationError
from rangekit.geometry import rotation_angle
from rangekit.registration.coarse import CoarseOptions, coarse_align_seeds, compute_features
from rangekit.registration.icp import IcpOptions, icp
from rangekit.registration.multiview import EdgeResult, MultiViewOptions, MultiViewResult, register_views
from rangekit.surface.cloud import PointCloud, bbox_diagonal, downsample_with_normals, merge_clouds

__all__ = ["PassesResult", "register_passes"]


@dataclass(frozen=True, eq=False)
class PassesResult:
    """A multi-pass registration: ``T_world_view`` (n, 4, 4), world = view 0; ``edges`` the passes' own view
    graphs (global view indices) then one edge per later pass to the first (``i``, ``j`` = the passes'
    first views, ``T_i_j`` the passes' relative pose, ``reason`` how it was found); ``sync`` the residuals
    of the passes' accepted edges in order; ``rmse`` the passes' own (their views' mean), metres."""

    T_world_view: np.ndarray
    edges: tuple[EdgeResult, ...]
    sync: object
    rmse: float
    passes: tuple[MultiViewResult, ...]
    T_first_pass: np.ndarray          # (passes, 4, 4) each pass's world (its first view) in the first's


@dataclass(frozen=True)
class _Residuals:
    edge_rotation_error: np.ndarray
    edge_translation_error: np.ndarray


def _align_pass(source: PointCloud, target: PointCloud, voxel: float, fine: float, p: int,
                options: MultiViewOptions) -> tuple[np.ndarray, EdgeResult]:
    """``T_first_p`` (pass p's merged cloud into the first pass's; both merged from the views' clouds at
    the fine voxel) with no prior, and its edge record."""
    copt = CoarseOptions(voxel=voxel, rng=options.rng)
    coarse_s, coarse_t = (compute_features(c, copt) for c in (source, target))   # features once for every seed
    def accept(r) -> bool:
        return r.rmse < options.max_coarse_rmse * voxel and r.fitness >= options.min_overlap

    try:
        found = coarse_align_seeds(coarse_s, coarse_t, copt, accept)
    except RegistrationError:
        found = None
    if found is None or not accept(found):
        seen = "no fit" if found is None else f"ICP RMSE {found.rmse * 1e3:.3f} mm, fitness {found.fitness:.2f}"
        raise RegistrationError(f"pass {p + 1}: no alignment to pass 1 found without a prior (expected an ICP-verified "
                                f"RMSE below {options.max_coarse_rmse * voxel * 1e3:.3f} mm and a fitness of at least "
                                f"{options.min_overlap:.2f}, found {seen}); the passes "
                                "may not overlap: turn the object less far over or scan more views")
    r = icp(source, target, init_T_target_source=found.T_target_source,
            options=IcpOptions(method="point_to_plane", kernel="huber", max_distance=2 * fine, max_iterations=60,
                               tolerance=1e-7, max_samples=20000))
    edge = EdgeResult(-1, -1, r.T_target_source, r.rmse, r.fitness, True,
                      f"pass {p + 1} to pass 1, no prior: {found.reason}; fine ICP rmse {r.rmse * 1e3:.3f} mm")
    return r.T_target_source, edge


def register_passes(clouds: Sequence[PointCloud], view_pass: Sequence[int], priors: Sequence[np.ndarray | None], *,
                    options: MultiViewOptions = MultiViewOptions(turntable=True),
                    progress: Callable[[str], None] | None = None,
                    names: Sequence[str] | None = None, map_pairs=None) -> PassesResult:
    """Register a multi-pass scan (see the module docstring).

    ``clouds``: every view in its own frame; ``view_pass`` (n,) each view's pass (0, 1, ...; every pass
    non-empty, in order); ``priors``: per pass the (m_p, 4, 4) prior of its views (the turntable's), or
    None (coarse alignment within the pass too). ``options``: those of each pass's registration (its
    ``voxel``, ``fine_voxel``, ``max_coarse_rmse``, ``min_overlap`` and ``rng`` also those of the alignment
    between passes). ``map_pairs``: runs each pass's pair refinements (see :func:`register_views`).
    Raises RegistrationError when a pass cannot be aligned to the first.
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
                             names=None if names is None else [names[k] for k in g], map_pairs=map_pairs)
        results.append(res)
        edges += [replace(e, i=int(g[e.i]), j=int(g[e.j])) for e in res.edges]
        rot.append(res.sync.edge_rotation_error)
        tr.append(res.sync.edge_translation_error)
    diag = bbox_diagonal(clouds)
    voxel = diag / 110.0 if options.voxel is None else options.voxel
    fine = voxel / 3.0 if options.fine_voxel is None else options.fine_voxel
    fine_clouds = [downsample_with_normals(c, fine) for c in clouds]
    merged = [downsample_with_normals(merge_clouds([fine_clouds[k] for k in g], r.T_world_view), fine)
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
    n = np.array([len(g) for g in groups])
    rmse = float(np.sum(n * [r.rmse for r in results]) / n.sum())
    return PassesResult(T, tuple(edges), _Residuals(np.concatenate(rot), np.concatenate(tr)), float(rmse),
                        tuple(results), np.stack(T_first))
