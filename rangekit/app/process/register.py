"""The register stage: the decoded views in one frame, seeded by the turntable angles, each pass of a multi-pass
scan from its prior and the passes to each other without one; the poses written to ``poses.json``."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from rangekit.app.process.decode import DecodedViews
from rangekit.formats.poses import save_poses
from rangekit.formats.sessions.session import Session, SessionView
from rangekit.formats.sessions.summary import Edge
from rangekit.rig.rig_file import turntable_prior
from rangekit.formats.sessions.files import POSES_FILE

if TYPE_CHECKING:
    from rangekit.registration.ahead import RegistrationAhead
    from rangekit.registration.multiview import MultiViewOptions

__all__ = ["RegisteredViews", "evaluator_angles", "register", "register_session_passes", "turntable_registration",
           "held_to_prior", "PRIOR_TRUST_DEG"]

#: Degrees a registration may move a view from the turntable's pose. A turntable's steps and calibrated axis
#: are good to a fraction of a degree (the simulated 12-view scan: 0.001 deg); a view moved further was slid by
#: ICP on too little shape (a 4-view scan with a 320x256 camera ended 46 deg off with exit 0).
PRIOR_TRUST_DEG = 5.0


@dataclass(frozen=True, eq=False)
class RegisteredViews:
    """The views in one frame: what the fusion, the evaluation and the report all take (made once)."""

    decoded: DecodedViews
    T_world_view: np.ndarray      # (n, 4, 4) registered poses, world = the first view's frame
    edges: list[Edge]             # the registration's view pairs (rangekit.formats.sessions.summary)
    rmse: float                   # metres: the joint point-to-plane RMS of the final poses
    view_passes: list[int] | None  # a multi-pass scan: each view's turntable pass; None for one pass
    note: str = ""                # what went wrong and what was done (the turntable's poses kept), else ""

    @property
    def angles(self) -> list:
        """The evaluator's key of each view: its turntable angle (radians), with its pass in a multi-pass scan."""
        return evaluator_angles(self.decoded.views, multi_pass=self.view_passes is not None)

    # What an evaluator reads of the views (rangekit.app.process.evaluate.RegisteredViewsLike), with T_world_view:
    @property
    def clouds(self) -> list:
        """Each view's cloud in its own frame."""
        return self.decoded.clouds

    @property
    def proj_cols(self) -> list:
        """Each view's decoded (H, W) projector columns, NaN where undecoded (emptied once measured)."""
        return self.decoded.proj_cols

    @property
    def names(self) -> list[str]:
        return self.decoded.names


def evaluator_angles(views: Sequence[SessionView], *, multi_pass: bool) -> list:
    """The evaluator's key of each view (:mod:`rangekit.app.process.evaluate`): its turntable angle (radians),
    with its pass, ``(angle, pass)``, in a multi-pass scan. Known before the views are registered."""
    return [(v.angle, v.scan_pass) for v in views] if multi_pass else [v.angle for v in views]


def turntable_registration(rig, views: Sequence[SessionView], first_cloud) -> tuple[np.ndarray, "MultiViewOptions"]:
    """``(prior, options)`` of a one-pass turntable session's registration: the turntable's poses of ``views``
    (world = the first view's frame) and the options that keep the joint refinement's views rotations about one
    axis, with the voxel the first view's cloud sweeps (:func:`rangekit.registration.turntable.swept_voxel`), so
    that a scan can register its views as they come (:class:`rangekit.registration.ahead.RegistrationAhead`)
    and give the same poses as processing the session afterwards. A first view of under 50 points (which
    registration refuses) leaves the voxel to the default rule."""
    from rangekit.registration.multiview import MultiViewOptions
    from rangekit.registration.turntable import swept_voxel

    prior = turntable_prior(rig.T_world_table, [v.angle for v in views])
    points = first_cloud.points
    ok = len(points) >= 50 and bool(np.all(np.isfinite(points)))
    return prior, MultiViewOptions(turntable=True, voxel=swept_voxel(points, prior) if ok else None)


def register(decoded: DecodedViews, session: Session, *, progress=None, map_pairs=None,
             ahead: RegistrationAhead | None = None) -> RegisteredViews:
    """Register the decoded views and write ``poses.json``. ``progress(msg)``: the registration's lines;
    ``map_pairs``: runs the pair refinements where the runner places them (e.g. as Dask tasks,
    :data:`rangekit.registration.pair_refine.PairMapper`; None: threads here); ``ahead``: what a scan's live
    processing registered as the views came (the runner's memo), taken where it is what this registration
    computes."""
    from rangekit.registration.multiview import MultiViewOptions, register_views

    views, clouds, rig = decoded.views, decoded.clouds, session.rig
    view_passes = [v.scan_pass for v in views] if session.plan.passes > 1 else None
    if view_passes is not None:    # each pass from its turntable prior, the passes to each other without one
        res = register_session_passes(clouds, views, rig, progress=progress, map_pairs=map_pairs)
    else:
        prior, options = (None, MultiViewOptions()) if rig.T_world_table is None else \
            turntable_registration(rig, views, clouds[0])
        res = register_views(clouds, init_T_world_view=prior, progress=progress, options=options,
                             map_pairs=map_pairs, ahead=ahead if ahead is not None and ahead.n == len(views) else None)
    T, note = res.T_world_view, ""
    if view_passes is None and prior is not None:
        T, note = held_to_prior(res.T_world_view, prior, decoded.names, converged=res.converged)
        if note:
            from rangekit.progress import LOGGER

            LOGGER.warning(note)
    save_poses(session.folder / POSES_FILE, decoded.names, T,
               world=f"frame of {views[0].folder.name} (the rig's world at its turntable angle)",
               extra=None if view_passes is None else [{"pass": p} for p in view_passes])
    edges = _edge_rows(res)
    return RegisteredViews(decoded, T, edges, float(res.rmse), view_passes, note)


def held_to_prior(T_world_view: np.ndarray, prior: np.ndarray, names: list[str], *,
                  converged: bool = True) -> tuple[np.ndarray, str]:
    """The registered poses, or the turntable's (``prior``, (n, 4, 4), expressed in the first view's frame) when
    the registration moved a view more than :data:`PRIOR_TRUST_DEG` from it; with a note saying which view
    and how far (and, ``converged`` False, that the joint refinement did not converge), else ""."""
    from rangekit.metrology.pose_errors import pose_errors

    P = np.einsum("ij,njk->nik", np.linalg.inv(prior[0]), prior)
    moved = pose_errors(T_world_view, P).rotation_deg
    worst = int(np.argmax(moved))
    unconverged = "" if converged else "; the joint refinement did not converge"
    if moved[worst] > PRIOR_TRUST_DEG:
        return P, (f"registration moved {names[worst]} {moved[worst]:.1f} deg from its turntable pose (more than "
                   f"{PRIOR_TRUST_DEG:g} deg){unconverged}: the turntable's poses are kept; too little shape overlaps "
                   f"between views (more views, or a larger camera image, give ICP more to hold on to)")
    if not converged:
        return T_world_view, (f"registration: the joint refinement did not converge (views within "
                              f"{moved.max():.2f} deg of the turntable's poses); the poses may be slightly off")
    return T_world_view, ""


def _edge_rows(res) -> list[Edge]:
    """The registration's view pairs, each accepted one with its synchronisation residuals (radians, metres)."""
    edges, k_acc = [], 0
    for e in res.edges:
        rotation = translation = None
        if e.accepted and k_acc < len(res.sync.edge_rotation_error):
            rotation = float(res.sync.edge_rotation_error[k_acc])
            translation = float(res.sync.edge_translation_error[k_acc])
            k_acc += 1
        edges.append(Edge(int(e.i), int(e.j), float(e.rmse), float(e.overlap), bool(e.accepted), e.reason, rotation,
                          translation))
    return edges


def register_session_passes(clouds, views, rig, *, progress=None, map_pairs=None):
    """Register a multi-pass session's views (:func:`rangekit.registration.passes.register_passes`): each
    pass from the turntable prior of its angles (None without a turntable in the rig), the passes to each
    other without a prior. ``views``: the session's done views (``scan_pass``, ``angle``); ``map_pairs``: see
    :func:`rangekit.registration.multiview.register_views`."""
    import numpy as np

    from rangekit.registration.multiview import MultiViewOptions
    from rangekit.registration.passes import register_passes
    from rangekit.rig.rig_file import turntable_prior

    vp = np.array([v.scan_pass for v in views])
    passes = sorted(set(vp.tolist()))
    remap = {p: k for k, p in enumerate(passes)}    # passes with no view done are left out
    priors = [None if rig.T_world_table is None else
              turntable_prior(rig.T_world_table, [v.angle for v in views if v.scan_pass == p]) for p in passes]
    return register_passes(clouds, [remap[p] for p in vp.tolist()], priors, progress=progress,
                           names=[v.folder.name for v in views],
                           options=MultiViewOptions(turntable=rig.T_world_table is not None), map_pairs=map_pairs)
