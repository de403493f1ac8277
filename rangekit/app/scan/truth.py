"""The simulator's truth for a simulated session: the evaluator that processing is given (processing itself never
imports the simulator, :mod:`rangekit.app.process.process`)."""

from __future__ import annotations

import numpy as np

from rangekit.app.process.evaluate import Evaluator
from rangekit.formats.sessions.session import Session

__all__ = ["session_evaluator"]


def session_evaluator(session: Session) -> Evaluator | None:
    """The simulator's truth for a simulated session (:func:`rangekit.sim.truth.evaluate.truth_evaluator`);
    None on hardware."""
    if session.simulator is None:
        return None
    from rangekit.sim.truth.evaluate import truth_evaluator

    motions = session.simulator.pass_motions    # the truth of a multi-pass scan: how the object was turned over
    return truth_evaluator(session.simulator_object, session.rig, light="laser" if session.is_laser else "projector",
                           **({"pass_motions": np.array(motions)} if motions is not None else {}))
