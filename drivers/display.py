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
from rangekit.drivers.retry import retry
from rangekit.errors import DeviceDisconnected, DeviceError, one_line

__all__ = ["PygameProjector"]

_CHECK = "check the projector's power, its video cable and input, and that the display is still connected"


class PygameProjector:
    """A :class:`rangekit.rig.devices.Projector` that shows images full-screen on one monitor.

    Parameters
    ----------
    calibration : PinholeCamera of the projector (its width x height is the window size).
    display : SDL display index of the projector's monitor (0 = primary).
    fullscreen : borderless full-screen window (False: an ordinary window, for trying it out).

    ``shown_at`` is the ``time.monotonic()`` after the last pattern was flipped to the screen; acquisition
    uses it to drop camera frames exposed before the change. A display that goes away (SDL sees fewer
    displays, or its window fails) raises DeviceDisconnected from :meth:`show`; :meth:`reconnect` opens the
    window again.
    """

    def __init__(self, calibration: PinholeCamera, *, display: int = 1, fullscreen: bool = True) -> None:
        try:
            os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
            import pygame
        except ImportError as exc:
            raise DeviceError("the projector display backend needs pygame: pip install 'rangekit[display]'") from exc
        self._pg = pygame
        self._model = calibration
        self.display, self._fullscreen = int(display), fullscreen
        self._open()
        self.shown_at = 0.0

    def _open(self) -> None:
        """(Re)start SDL's video and open the window on ``display``. DeviceError if the display is not there."""
        pygame, calibration, display = self._pg, self._model, self.display
        try:
            pygame.display.quit()
            pygame.display.init()
            n = pygame.display.get_num_displays()
            if not 0 <= display < n:
                raise DeviceError(f"projector display {display} does not exist: SDL sees {n} display(s) "
                                  f"(0..{n - 1}); connect the projector and choose its index")
            flags = pygame.NOFRAME | (pygame.FULLSCREEN if self._fullscreen else 0)
            self._screen = pygame.display.set_mode((calibration.width, calibration.height), flags, display=display)
            pygame.mouse.set_visible(False)
            size = self._screen.get_size()
            if size != (calibration.width, calibration.height):
                raise DeviceError(f"projector display {display}: the window is {size[0]}x{size[1]}, the projector's "
                                  f"calibration {calibration.width}x{calibration.height}; set the display to the "
                                  "projector's native resolution (or choose its display index)")
        except pygame.error as exc:
            raise DeviceError(f"cannot open a {calibration.width}x{calibration.height} window on display {display}: "
                              f"{one_line(exc)}") from exc

    def reconnect(self, timeout_s: float) -> None:
        """Open the window again, retried until ``timeout_s`` seconds have passed: after the projector's display
        went away mid-scan (video cable, power, input switched). DeviceDisconnected if it is not back in time."""
        try:
            retry(lambda left_s: self._open(), timeout_s, errors=(DeviceError,))
        except DeviceError as exc:
            raise DeviceDisconnected(f"projector display {self.display}: not back within {timeout_s:g} s ({exc}); "
                                     f"{_CHECK}") from exc

    @property
    def calibration(self) -> PinholeCamera:
        return self._model

    @property
    def resolution(self) -> tuple[int, int]:
        return self._model.width, self._model.height

    def show(self, image: np.ndarray) -> None:
        """Display ``image`` ((H, W) or (H, W, 3) uint8, projector size) until the next call."""
        img = check_pattern(image, self.resolution, self._model.name)
        rgb = np.ascontiguousarray(np.repeat(img[:, :, None], 3, axis=2) if img.ndim == 2 else img, dtype=np.uint8)
        pg = self._pg
        try:
            pg.event.pump()  # keep the window responsive
            n = pg.display.get_num_displays()
            if self.display >= n:
                raise DeviceDisconnected(f"projector display {self.display}: gone, SDL sees {n} display(s) now; "
                                         f"{_CHECK}")
            # one copy of the rows as they are (a transposed blit_array copy took 15 ms at 1024x768, a 60 Hz frame)
            self._screen.blit(pg.image.frombuffer(rgb, self.resolution, "RGB"), (0, 0))
            pg.display.flip()
        except pg.error as exc:
            raise DeviceDisconnected(f"projector display {self.display}: lost ({one_line(exc)}); {_CHECK}") from exc
        self.shown_at = time.monotonic()

    def displayed(self) -> np.ndarray:
        """(H, W, 3) uint8: what the window shows now (for checks)."""
        return self._pg.surfarray.array3d(self._screen).swapaxes(0, 1).copy()

    def close(self) -> None:
        self._pg.display.quit()
