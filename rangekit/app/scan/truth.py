"""The simulator's truth for a simulated session: the :class:`~rangekit.app.process.evaluate.Truth` that processing
is given (processing itself never imports the simulator, :mod:`rangekit.app.process.process`); a hardware session's
is :data:`~rangekit.app.process.evaluate.NO_TRUTH`."""

from __future__ import annotations

import numpy as np

from rangekit.app.process.evaluate import NO_TRUTH, Truth
from rangekit.formats.sessions.session import Session

__all__ = ["session_evaluator"]


def session_evaluator(session: Session) -> Truth:
    """The simulator's truth for a simulated session (:func:`rangekit.sim.truth.evaluate.truth_evaluator`);
    :data:`~rangekit.app.process.evaluate.NO_TRUTH` (measures nothing) on hardware."""
    if session.simulator is None:
        return NO_TRUTH
    from rangekit.sim.truth.evaluate import truth_evaluator

    motions = session.simulator.pass_motions    # the truth of a multi-pass scan: how the object was turned over
    return truth_evaluator(session.simulator_object, session.rig, light="laser" if session.is_laser else "projector",
                           **({"pass_motions": np.array(motions)} if motions is not None else {}))
