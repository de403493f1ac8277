"""Show patterns on a projector connected as a monitor (HDMI), full-screen, through pygame.

pygame is an optional extra (``pip install rangekit[display]``) and is imported only when a display is
opened. The projector's pixels must map one to one: open the window at the projector's native
resolution on its monitor (``display`` index as SDL numbers them).
"""

from __future__ import annotations

import os
import time

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.rig.devices import check_pattern
from rangekit.errors import DeviceError

__all__ = ["PygameProjector"]


class PygameProjector:
    """A :class:`rangekit.rig.devices.Projector` that shows images full-screen on one monitor.

    Parameters
    ----------
    calibration : PinholeCamera of the projector (its width x height is the window size).
    display : SDL display index of the projector's monitor (0 = primary).
    fullscreen : borderless full-screen window (False: an ordinary window, for trying it out).

    ``shown_at`` is the ``time.monotonic()`` after the last pattern was flipped to the screen; acquisition
    uses it to drop camera frames exposed before the change.
    """

    def __init__(self, calibration: PinholeCamera, *, display: int = 1, fullscreen: bool = True) -> None:
        try:
            os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
            import pygame
        except ImportError as exc:
            raise DeviceError("the projector display backend needs pygame: pip install 'rangekit[display]'") from exc
        self._pg = pygame
        self._model = calibration
        try:
            pygame.display.init()
            n = pygame.display.get_num_displays()
            if not 0 <= display < n:
                raise DeviceError(f"projector display {display} does not exist: SDL sees {n} display(s) "
                                  f"(0..{n - 1}); connect the projector and choose its index")
            flags = pygame.NOFRAME | (pygame.FULLSCREEN if fullscreen else 0)
            self._screen = pygame.display.set_mode((calibration.width, calibration.height), flags, display=display)
            pygame.mouse.set_visible(False)
        except pygame.error as exc:
            raise DeviceError(f"cannot open a {calibration.width}x{calibration.height} window on display {display}: "
                              f"{exc}") from exc
        self.shown_at = 0.0

    @property
    def calibration(self) -> PinholeCamera:
        return self._model

    @property
    def resolution(self) -> tuple[int, int]:
        return self._model.width, self._model.height

    def show(self, image: np.ndarray) -> None:
        """Display ``image`` ((H, W) or (H, W, 3) uint8, projector size) until the next call."""
        img = check_pattern(image, self.resolution, self._model.name)
        rgb = np.repeat(img[:, :, None], 3, axis=2) if img.ndim == 2 else img
        self._pg.event.pump()  # keep the window responsive
        self._pg.surfarray.blit_array(self._screen, np.ascontiguousarray(rgb.swapaxes(0, 1)))
        self._pg.display.flip()
        self.shown_at = time.monotonic()

    def displayed(self) -> np.ndarray:
        """(H, W, 3) uint8: what the window shows now (for checks)."""
        return self._pg.surfarray.array3d(self._screen).swapaxes(0, 1).copy()

    def close(self) -> None:
        self._pg.display.quit()
