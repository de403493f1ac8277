"""What lights the object for each frame of a view: the projector showing a pattern, or one line laser.

:func:`rangekit.app.acquire.acquire.acquire` calls ``light.show(i)`` before capturing frame ``i`` of a view,
``light.show(None)`` after the view's last frame, ``light.reset()`` before a view is taken again (after a device
came back), and ``light.close()`` when acquisition ends (also on a fault or an interrupt): the lasers are then
switched off, so a stopped scan never leaves a laser on.

Laser order at each turntable step (one frame per laser, the others off): the laser-off frame with every
laser off, then for laser k: on (``turntable.laser(switch_k, True)``: ``M71T<n>`` on Horus firmware), the
frame, off (``M70T<n>``). The board numbers lasers by their rig file ``switch`` (default 1, 2, ...).
"""

from __future__ import annotations

from rangekit.coded.patterns import PatternSpec
from rangekit.errors import ConfigError, DeviceError
from rangekit.laser.sequence import LaserSequence
from rangekit.rig.rig_file import Rig

__all__ = ["light_for", "ProjectorLight", "LaserLight"]


class ProjectorLight:
    """Frame ``i`` is pattern ``i`` of the spec, shown by the projector."""

    device = "projector"

    def __init__(self, projector, spec: PatternSpec) -> None:
        self._projector, self._frames = projector, list(spec.frames())

    def show(self, frame: int | None) -> None:
        if frame is not None:
            self._projector.show(self._frames[frame])

    def reset(self) -> None:
        """Nothing to do: every frame shows its pattern."""

    def close(self) -> None:
        pass


class LaserLight:
    """Frame 0 with every laser off, frame k + 1 with laser k alone on, switched by the turntable board."""

    device = "lasers"

    def __init__(self, board, spec: LaserSequence, rig: Rig) -> None:
        self._board, self._spec = board, spec
        self._switch = [laser.switch if laser.switch is not None else k + 1 for k, laser in enumerate(rig.lasers)]
        self._on: int | None = None
        self.reset()

    def reset(self) -> None:
        """Every laser off: a known state (a board may start with a laser on, or have lost a command)."""
        self._on = None
        for n in self._switch:
            self._board.laser(n, False)

    def show(self, frame: int | None) -> None:
        want = None if frame is None else self._spec.lit(frame)
        if self._on is not None and self._on != want:
            self._board.laser(self._switch[self._on], False)
            self._on = None
        if want is not None and self._on != want:
            self._board.laser(self._switch[want], True)
            self._on = want

    def close(self) -> None:
        """Every laser off; a board that fails here has already failed the scan (its error is the one shown)."""
        if self._on is not None:
            try:
                self._board.laser(self._switch[self._on], False)
            except DeviceError:
                pass
            self._on = None


def light_for(devices, spec: PatternSpec | LaserSequence, rig: Rig):
    """The light of ``spec``: a :class:`LaserLight` on ``devices.turntable`` for a laser sequence (the rig
    must have that many lasers), else a :class:`ProjectorLight` on ``devices.projector``."""
    if isinstance(spec, LaserSequence):
        if len(rig.lasers) != spec.n_lasers:
            raise ConfigError(f"the rig has {len(rig.lasers)} laser(s) (rig file 'lasers'); the scan takes "
                              f"{spec.n_lasers}")
        board = devices.turntable
        if board is None or not callable(getattr(board, "laser", None)):
            raise ConfigError("a laser scan switches the lasers through the turntable board; this rig's turntable "
                              f"({type(board).__name__}) has no laser switch")
        return LaserLight(board, spec, rig)
    if devices.projector is None:
        raise ConfigError("a coded-light scan needs a projector; this rig has none")
    return ProjectorLight(devices.projector, spec)
