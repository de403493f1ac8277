"""The evaluate stage: the scan measured against the truth by an evaluator that processing is given (the
simulator's, :func:`rangekit.sim.truth.evaluate.truth_evaluator`; none on hardware). Processing never imports
the simulator.

The runner (:mod:`rangekit.app.process.process`) runs it in parts around the registration and the fusion: the
truth's mesh-independent part beside the registration (:meth:`Evaluator.prepare`), the views beside the fusion
(:func:`measure_views`), the observed mesh while the closed one is made
(:func:`rangekit.app.process.fused_outputs.evaluate_observed`), the closed mesh at the end (:func:`measure_closed`).
"""

from __future__ import annotations

from typing import Protocol, Sequence

import numpy as np

from rangekit.app.process.fuse import FusedViews
from rangekit.app.process.fused_outputs import with_closed
from rangekit.app.process.register import RegisteredViews
from rangekit.camera import forget_pixel_rays
from rangekit.formats.sessions.summary import Accuracy
from rangekit.formats.sessions.view_errors import ViewErrors
from rangekit.surface.mesh import TriangleMesh

__all__ = ["Evaluation", "Truth", "Evaluator", "NoTruth", "NO_TRUTH", "measuring", "RegisteredViewsLike",
           "measure_views", "measure_closed"]


class Evaluation(Protocol):
    """What an evaluator returns: the mesh's :class:`Accuracy`, ``truth`` (the true surface in the session world,
    for the report's heat map) and ``view_errors`` (the per-view breakdown, the summary's "view_errors", or None)."""

    accuracy: Accuracy
    truth: TriangleMesh
    view_errors: ViewErrors | None


class RegisteredViewsLike(Protocol):
    """What an evaluator reads of the registered views (:class:`rangekit.app.process.register.RegisteredViews`):
    each view's cloud in its own frame, the registered (n, 4, 4) ``T_world_view``, the decoded (H, W)
    projector columns (emptied once measured) and the views' names."""

    clouds: Sequence
    T_world_view: np.ndarray
    proj_cols: list
    names: list[str]


class Truth(Protocol):
    """What a scan is measured against; processing is given one and never imports the simulator (which provides
    it: :func:`rangekit.sim.truth.evaluate.truth_evaluator`); on hardware :data:`NO_TRUTH`.

    ``measures``: False when there is nothing to measure against (:class:`NoTruth`): the stages then skip the
    evaluation (:func:`measuring`). ``truth(mesh, angles, cloud=None, views=None)``: the fused mesh (session world)
    and the views' turntable angles (radians; ``(angle, pass)`` pairs in a multi-pass scan) to an
    :class:`Evaluation`; ``cloud`` the merged points (session world), ``views`` the registered views for the
    per-view breakdown. ``prepare(angles, views)`` computes ahead, beside the fusion, what does not depend on the
    mesh (the same ``views`` object is then recognised by identity). ``prepare_view(angles, k, cloud, proj_col)``:
    view ``k``'s errors that its registered pose does not change, measured as the view is decoded (a scan's
    streaming processor), taken by ``prepare`` when its ``views`` hold these very objects."""

    measures: bool

    def __call__(self, mesh: TriangleMesh, angles: Sequence, cloud: np.ndarray | None = None,
                 views: RegisteredViewsLike | None = None) -> Evaluation: ...

    def prepare(self, angles: Sequence, views: RegisteredViewsLike | None = None) -> None: ...

    def prepare_view(self, angles: Sequence, k: int, cloud, proj_col: np.ndarray | None = None) -> None: ...


#: The name processing has used for a :class:`Truth`.
Evaluator = Truth


class NoTruth:
    """The truth of a hardware scan: nothing to measure against (``measures`` False); preparing does nothing, and
    measuring is refused (the stages do not call it: :func:`measuring`)."""

    measures = False

    def __call__(self, mesh, angles, cloud=None, views=None) -> Evaluation:
        raise TypeError("NoTruth: a hardware scan has no truth to measure against (check Truth.measures first)")

    def prepare(self, angles, views=None) -> None:
        return None

    def prepare_view(self, angles, k, cloud, proj_col=None) -> None:
        return None

    def __repr__(self) -> str:
        return "NO_TRUTH"


#: The one :class:`NoTruth`.
NO_TRUTH = NoTruth()


def measuring(truth: Truth | None) -> Truth | None:
    """``truth`` when it measures, else None: the stages take None as "no evaluation"."""
    return truth if truth is not None and truth.measures else None


def measure_views(evaluate: Evaluator | None, registered: RegisteredViews) -> None:
    """Beside the fusion: the evaluator's ``prepare`` (each view against the truth), after which the decoded
    projector columns (12 maps, 63 MB) are let go; then the camera's cached rays (63 MB, used by the decoding
    and the per-view errors) are let go, with or without an evaluator. (The runner has the views' casts and
    distances reuse freed pages, :func:`rangekit._runtime.memory.reuse_freed_memory`: 0.8 GB of fresh pages
    faulted in and zeroed on the 12-view scan became 0.12 GB, with the same peak, issue 36.)"""
    if evaluate is not None:
        evaluate.prepare(registered.angles, registered)
        registered.decoded.proj_cols.clear()   # made into the per-view errors: not kept beside Poisson
    forget_pixel_rays()


def measure_closed(evaluate: Evaluator, fused: FusedViews,
                   registered: RegisteredViews) -> tuple[Accuracy, TriangleMesh, ViewErrors | None]:
    """The observed mesh's :class:`Accuracy` with the closed mesh's figures as its ``watertight``: ``(accuracy,
    truth, view errors)`` (:func:`rangekit.app.process.fused_outputs.with_closed`)."""
    return with_closed(evaluate, fused.evaluation, fused.watertight, registered.angles)
