"""Who moves the calibration board between captures (``rangekit calibrate``): on hardware a person, asked by
``ask(prompt)`` (e.g. ``input``) with a hint for each pose; on the simulator the code, which sets the board's scene.
Each placer gives :func:`rangekit.calib.procedure.calibrate_rig` its ``place_board(i, n)`` and
``place_on_turntable()``."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from rangekit.boards import Board
from rangekit.rig.rig_file import Rig

__all__ = ["POSE_HINTS", "AskedPlacer", "SimulatedPlacer"]

#: Where a person is asked to hold the board, pose by pose (in turn, again from the first after the last).
POSE_HINTS = ("facing the camera, tilted ~30 deg to the left", "tilted ~30 deg to the right",
              "top edge tilted ~30 deg away", "bottom edge tilted ~30 deg away",
              "turned ~20 deg in its plane, tilted left", "near the left edge of the view, tilted right",
              "near the right edge of the view, tilted left", "near the top of the view, tilted down",
              "near the bottom of the view, tilted up", "closer to the camera, tilted ~40 deg",
              "further away, tilted ~20 deg")


@dataclass(frozen=True, eq=False)
class AskedPlacer:
    """On hardware: the person holding ``board`` is asked (``ask(prompt)``) to place it and press Enter."""

    board: Board
    ask: Callable[[str], object]

    def place(self, i: int, n: int) -> None:
        """Pose ``i`` of ``n``: still, at :data:`POSE_HINTS`' hint, inside the projected light."""
        self.ask(f"pose {i + 1}/{n}: hold the {self.board.cols}x{self.board.rows} board still, "
                 f"{POSE_HINTS[i % len(POSE_HINTS)]}, wholly inside the projected light; press Enter to capture ")

    def on_turntable(self) -> None:
        """The board fixed on the turntable, visible over the angles the calibration turns it to."""
        self.ask("turntable: fix the board on the turntable, standing and tilted back towards the camera, off the "
                 "axis, so that it stays visible while the table turns +-40 deg; press Enter ")


@dataclass(frozen=True, eq=False)
class SimulatedPlacer:
    """On the simulator: ``devices`` (a :class:`rangekit.sim.SimRig`) shown ``board`` at each of ``poses``
    ((4, 4) ``T_world_board`` each, world = the true rig ``truth``'s), then on its turntable."""

    devices: object
    board: Board
    poses: list[np.ndarray]
    truth: Rig

    def place(self, i: int, n: int) -> None:
        """The board moved to pose ``i`` (of ``n``, as many as ``poses``)."""
        from rangekit.sim.writers.calibration import board_scene

        self.devices.set_scene(board_scene(self.board, self.poses[i]))

    def on_turntable(self) -> None:
        """The board moved onto the turntable of the true rig."""
        from rangekit.sim.writers.calibration import turntable_board_scene

        self.devices.set_scene(turntable_board_scene(self.truth, self.board))
