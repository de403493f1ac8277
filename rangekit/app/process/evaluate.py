"""The evaluate stage: the scan measured against the truth by an evaluator that processing is given (the
simulator's, :func:`rangekit.sim.truth.evaluate.truth_evaluator`; none on hardware). Processing never imports
the simulator.

It runs in three parts around the fusion: the views beside it (:func:`measure_views`), the observed mesh while
the closed one is made (:meth:`rangekit.app.process.fuse.Fusion.meshes`), the closed mesh at the end
(:func:`measure_closed`).
"""

from __future__ import annotations

from typing import Callable, Protocol, Sequence

from rangekit.app.events import OnEvent, StageClock, progress_of
from rangekit.app.process.fuse import FusedViews
from rangekit.app.process.fused_outputs import with_closed
from rangekit.app.process.register import RegisteredViews
from rangekit.camera import forget_pixel_rays
from rangekit.progress import call_progress

__all__ = ["Evaluation", "Evaluator", "measure_views", "measure_closed"]


class Evaluation(Protocol):
    """What an evaluator returns: ``accuracy`` (an object with ``to_dict()``, the summary's "accuracy"),
    ``truth`` (the true surface as a TriangleMesh in the session world, for the report's heat map) and
    ``view_errors`` (a list of per-view dicts, the summary's "view_errors", or None)."""

    accuracy: object
    truth: object
    view_errors: list | None


#: ``evaluate(mesh, angles, cloud=None, views=None)``: the fused mesh (session world) and the views'
#: turntable angles (radians) to an :class:`Evaluation`; ``cloud`` the merged points (session world),
#: ``views`` a dict of the views' ``clouds``, registered ``T_world_view``, decoded ``proj_cols`` and
#: ``names`` for the per-view breakdown. An evaluator may have ``prepare(angles, views)``, run beside the
#: fusion, after which ``views["proj_cols"]`` is emptied (made into the per-view errors, not kept).
#: The simulator provides one (:func:`rangekit.sim.truth.evaluate.truth_evaluator`).
Evaluator = Callable[[object, Sequence[float]], Evaluation]


def measure_views(evaluate: Evaluator | None, registered: RegisteredViews, clock: StageClock) -> None:
    """Beside the fusion: the evaluator's ``prepare`` (each view against the truth), after which the decoded
    projector columns (12 maps, 63 MB) are let go; then the camera's cached rays (63 MB, used by the decoding
    and the per-view errors) are let go, with or without an evaluator."""
    prepare = getattr(evaluate, "prepare", None)
    if prepare is not None:
        with clock.stage("evaluate"):
            prepare(registered.angles, registered.evaluator_views)
        registered.decoded.proj_cols.clear()   # made into the per-view errors: not kept beside Poisson
    forget_pixel_rays()


def measure_closed(evaluate: Evaluator, fused: FusedViews, registered: RegisteredViews, clock: StageClock,
                   on_event: OnEvent | None = None) -> tuple[dict, object, list | None]:
    """The observed mesh's figures with the closed mesh's under ``"watertight"``: ``(accuracy dict, truth,
    view errors)`` (:func:`rangekit.app.process.fused_outputs.with_closed`)."""
    with clock.stage("evaluate"):
        call_progress(progress_of(on_event), "measuring the closed mesh against the true surface")
        return with_closed(evaluate, fused.evaluation, fused.watertight, registered.angles)
