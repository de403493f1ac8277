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
from rangekit.surface.mesh import TriangleMesh

__all__ = ["Evaluation", "Evaluator", "RegisteredViewsLike", "measure_views", "measure_closed"]


class Evaluation(Protocol):
    """What an evaluator returns: the mesh's :class:`Accuracy`, ``truth`` (the true surface in the session world,
    for the report's heat map) and ``view_errors`` (a list of per-view dicts, the summary's "view_errors", or
    None)."""

    accuracy: Accuracy
    truth: TriangleMesh
    view_errors: list | None


class RegisteredViewsLike(Protocol):
    """What an evaluator reads of the registered views (:class:`rangekit.app.process.register.RegisteredViews`):
    each view's cloud in its own frame, the registered (n, 4, 4) ``T_world_view``, the decoded (H, W)
    projector columns (emptied once measured) and the views' names."""

    clouds: Sequence
    T_world_view: np.ndarray
    proj_cols: list
    names: list[str]


class Evaluator(Protocol):
    """Measures a scan against the truth; processing is given one and never imports the simulator (which
    provides it: :func:`rangekit.sim.truth.evaluate.truth_evaluator`).

    ``evaluate(mesh, angles, cloud=None, views=None)``: the fused mesh (session world) and the views' turntable
    angles (radians; ``(angle, pass)`` pairs in a multi-pass scan) to an :class:`Evaluation`; ``cloud`` the merged
    points (session world), ``views`` the registered views for the per-view breakdown. ``prepare(angles,
    views)`` computes ahead, beside the fusion, what does not depend on the mesh (the same ``views`` object is
    then recognised by identity)."""

    def __call__(self, mesh: TriangleMesh, angles: Sequence, cloud: np.ndarray | None = None,
                 views: RegisteredViewsLike | None = None) -> Evaluation: ...

    def prepare(self, angles: Sequence, views: RegisteredViewsLike | None = None) -> None: ...


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
                   registered: RegisteredViews) -> tuple[Accuracy, TriangleMesh, list | None]:
    """The observed mesh's :class:`Accuracy` with the closed mesh's figures as its ``watertight``: ``(accuracy,
    truth, view errors)`` (:func:`rangekit.app.process.fused_outputs.with_closed`)."""
    return with_closed(evaluate, fused.evaluation, fused.watertight, registered.angles)
