"""The register stage: the decoded views in one frame, seeded by the turntable angles, each pass of a multi-pass
scan from its prior and the passes to each other without one; the poses written to ``poses.json``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit._runtime.memory import release_free_memory
from rangekit.app.events import OnEvent, PairRegistered, StageClock, emit, progress_of
from rangekit.app.process.decode import DecodedViews
from rangekit.formats.poses import save_poses
from rangekit.formats.sessions.session import Session
from rangekit.formats.sessions.summary import Edge
from rangekit.rig.rig_file import turntable_prior

__all__ = ["RegisteredViews", "register"]


@dataclass(frozen=True, eq=False)
class RegisteredViews:
    """The views in one frame: what the fusion, the evaluation and the report all take (made once)."""

    decoded: DecodedViews
    T_world_view: np.ndarray      # (n, 4, 4) registered poses, world = the first view's frame
    edges: list[Edge]             # the registration's view pairs (rangekit.formats.sessions.summary)
    rmse: float                   # metres: the joint point-to-plane RMS of the final poses
    view_passes: list[int] | None  # a multi-pass scan: each view's turntable pass; None for one pass

    @property
    def angles(self) -> list:
        """The evaluator's key of each view: its turntable angle (radians), with its pass in a multi-pass scan."""
        views = self.decoded.views
        return [v.angle for v in views] if self.view_passes is None else [(v.angle, v.scan_pass) for v in views]

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


def register(decoded: DecodedViews, session: Session, clock: StageClock, on_event: OnEvent | None = None, *,
             map_pairs=None) -> RegisteredViews:
    """Register the decoded views (``map_pairs``: runs the pair refinements elsewhere, e.g. as Dask tasks,
    :data:`rangekit.registration.pair_refine.PairMapper`), write ``poses.json``, announce each pair as
    :class:`PairRegistered`."""
    from rangekit.registration.multiview import MultiViewOptions, register_views

    views, clouds, rig = decoded.views, decoded.clouds, session.rig
    view_passes = [v.scan_pass for v in views] if session.plan.passes > 1 else None
    progress = progress_of(on_event)
    with clock.stage("register"):
        if view_passes is not None:    # each pass from its turntable prior, the passes to each other without one
            from rangekit.app.scan.passes import register_session_passes

            res = register_session_passes(clouds, views, rig, progress=progress, map_pairs=map_pairs)
        else:
            prior = None if rig.T_world_table is None else turntable_prior(rig.T_world_table, [v.angle for v in views])
            # On the rig's turntable the views are rotations about one axis: the joint refinement keeps them so.
            res = register_views(clouds, init_T_world_view=prior, progress=progress,
                                 options=MultiViewOptions(turntable=prior is not None), map_pairs=map_pairs)
        save_poses(session.folder / "poses.json", decoded.names, res.T_world_view,
                   world=f"frame of {views[0].folder.name} (the rig's world at its turntable angle)",
                   extra=None if view_passes is None else [{"pass": p} for p in view_passes])
        edges = _edge_rows(res)
        for e in res.edges:
            emit(on_event, PairRegistered(e.i, e.j, float(e.rmse), float(e.overlap), bool(e.accepted), e.reason))
        release_free_memory()   # the registration's k-d trees and samples
    return RegisteredViews(decoded, res.T_world_view, edges, float(res.rmse), view_passes)


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
