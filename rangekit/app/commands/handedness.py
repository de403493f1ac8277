"""A mirrored scan among the scans given to ``rangekit register``: the check of its input after registration.

A scan whose handedness is flipped (one axis negated: a y-up/y-down or left-/right-handed mix-up on export)
is a valid surface on its own, so no single file shows it; next to the others it is the mirror image of the
object, which no rigid motion aligns. Registration then fits it as well as a rigid motion can: it is refused
(a "no reliable link" error), or, when the object is close to symmetric and a prior holds it near its place,
accepted with a residual several times the other pairs' and a wrong pose, and the command exits 0.

:func:`check_handedness` looks at the registered edges only (nothing more is computed while every view fits as
well as the others): a view whose best edge leaves an RMS residual :data:`SUSPICIOUS_RATIO` times the median of
the other views' accepted edges (with two scans: above :data:`SUSPICIOUS_VOXELS` voxels) is aligned again to
its most overlapping neighbour from scratch (FPFH + RANSAC + ICP, :func:`rangekit.registration.coarse.coarse_align`)
twice: as it is, and mirrored (x negated). When the mirror image fits within the registration's own acceptance
gate and leaves less than :data:`MIRROR_RATIO` of the rigid fit's residual, the scan is refused as mirrored.
An object with a mirror symmetry fits both ways equally well, and is never flagged (nor does it matter there).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from rangekit.errors import RegistrationError
from rangekit.registration.coarse import CoarseOptions, coarse_align
from rangekit.registration.multiview import MultiViewOptions, MultiViewResult
from rangekit.surface.cloud import PointCloud, bbox_diagonal, downsample_with_normals

__all__ = ["check_handedness", "mirror_fit", "SUSPICIOUS_RATIO", "SUSPICIOUS_VOXELS", "MIRROR_RATIO", "PARTNERS",
           "MIRROR"]

#: A view is tested when its best edge's RMS residual is this many times the median of the other views'
#: accepted edges (a good view of a turntable scan is within 1.5 times; a mirrored one 5 times and more).
SUSPICIOUS_RATIO = 3.0
#: With no other edges to compare with (two scans): tested above this many voxels (accepted: below 0.45).
SUSPICIOUS_VOXELS = 0.15
#: Mirrored when the mirror image leaves less than this fraction of the rigid fit's RMS residual.
MIRROR_RATIO = 0.5
#: The most overlapping neighbours a suspicious view is aligned to, mirrored and not.
PARTNERS = 3
#: The reflection tested: x negated (any reflection is this one followed by a rotation).
MIRROR = np.diag([-1.0, 1.0, 1.0])


def mirror_fit(source: PointCloud, target: PointCloud, voxel: float, *, rng: int = 0) -> tuple:
    """(rigid, mirrored): the :class:`rangekit.registration.icp.RegistrationResult` of ``source`` aligned to
    ``target`` from scratch as it is and with x negated (None where the coarse alignment finds nothing), both
    on clouds downsampled to ``voxel`` metres."""
    opt = CoarseOptions(voxel=voxel, rng=rng)
    src = downsample_with_normals(source, voxel)
    tgt = downsample_with_normals(target, voxel)
    flipped = PointCloud(src.points @ MIRROR, normals=None if src.normals is None else src.normals @ MIRROR)
    out = []
    for s in (src, flipped):
        try:
            out.append(coarse_align(s, tgt, opt))
        except RegistrationError:
            out.append(None)
    return tuple(out)


def check_handedness(clouds: Sequence[PointCloud], result: MultiViewResult, names: Sequence[str], *,
                     voxel: float | None = None, options: MultiViewOptions | None = None) -> None:
    """Raise :class:`RegistrationError` naming a scan of ``clouds`` (registered into ``result``) that looks
    mirrored, with the residual of its best rigid fit and of its mirror image; else return (module doc).
    ``voxel``: the registration's (None: its default, the bounding-box diagonal / 110); ``options``: its
    acceptance gates (default :class:`MultiViewOptions`)."""
    options = options or MultiViewOptions()
    n = len(clouds)
    voxel = voxel or bbox_diagonal(clouds) / 110.0
    edges = [e for e in result.edges if np.isfinite(e.rmse) and e.overlap >= options.min_overlap]
    suspicious = {}
    for k in range(n):
        mine = [e for e in edges if k in (e.i, e.j)]
        others = [e.rmse for e in result.edges if e.accepted and k not in (e.i, e.j)]
        typical = float(np.median(others)) if others else None
        if mine and min(e.rmse for e in mine) > (SUSPICIOUS_RATIO * typical if others else SUSPICIOUS_VOXELS * voxel):
            suspicious[k] = (mine, typical)
    for k, (mine, typical) in sorted(suspicious.items(), key=lambda kv: -min(e.rmse for e in kv[1][0])):
        # Its most overlapping neighbours first, those not suspicious themselves before the others.
        mine = sorted(mine, key=lambda e: ((e.j if e.i == k else e.i) in suspicious, -e.overlap))[:PARTNERS]
        for edge in mine:
            j = edge.j if edge.i == k else edge.i
            rigid, mirrored = mirror_fit(clouds[k], clouds[j], voxel, rng=options.rng)
            rigid_rmse = min(edge.rmse, rigid.rmse if rigid is not None and rigid.fitness >= options.min_overlap
                             else np.inf)
            if mirrored is None or mirrored.fitness < options.min_overlap:
                continue
            # Fits as the other pairs do (or, with two scans, within the acceptance gate), and far better than rigid.
            good = SUSPICIOUS_RATIO * typical if typical is not None else options.max_rmse * voxel
            if mirrored.rmse <= min(good, options.max_rmse * voxel) and mirrored.rmse < MIRROR_RATIO * rigid_rmse:
                who = (f"{names[k]} looks mirrored" if n > 2 else
                       f"{names[k]} and {names[j]} are mirror images of each other: one of them looks mirrored")
                raise RegistrationError(
                    f"{who} (its handedness flipped, as if one axis were negated): the best rigid fit of {names[k]} "
                    f"to {names[j]} leaves {rigid_rmse * 1e3:.3g} mm RMS, its mirror image fits with "
                    f"{mirrored.rmse * 1e3:.3g} mm ({mirrored.fitness:.0%} overlap); no rigid motion aligns it: "
                    "negate one axis of its points and normals and register again")
