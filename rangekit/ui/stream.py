"""The live camera stream: one thread grabbing frames from the rig while at least one page watches, at most
:data:`MAX_FPS` a second, each turned into a :class:`rangekit.ui.live.LiveFrame`; pages take the latest one
(a slow page skips frames, it never slows the camera or the others)."""

from __future__ import annotations

import threading
import time
from dataclasses import replace

from rangekit.errors import RangekitError
from rangekit.progress import LOGGER
from rangekit.ui.live import LiveFrame, live_frame
from rangekit.ui.rig_holder import RigHolder

__all__ = ["MAX_FPS", "LiveStream"]

#: The stream's ceiling, frames a second.
MAX_FPS = 15.0


class LiveStream:
    """Frames of ``holder``'s camera for the pages that watch (:meth:`watch` / :meth:`unwatch`)."""

    def __init__(self, holder: RigHolder, max_fps: float = MAX_FPS) -> None:
        self.holder, self.period = holder, 1.0 / float(max_fps)
        self._cond = threading.Condition()
        self._latest: LiveFrame | None = None
        self._watchers = 0
        self._stop = False
        self.error: str | None = None
        #: ``annotate(image) -> dict`` adds figures to each frame (the Calibrate page's live board corners)
        self.annotate = None
        self._thread = threading.Thread(target=self._run, name="rangekit-live", daemon=True)
        self._thread.start()

    def watch(self) -> None:
        with self._cond:
            self._watchers += 1
            self._cond.notify_all()

    def unwatch(self) -> None:
        with self._cond:
            self._watchers = max(0, self._watchers - 1)

    def latest(self) -> LiveFrame | None:
        return self._latest

    def next_after(self, seq: int, timeout: float) -> LiveFrame | None:
        """The first frame newer than ``seq``, waiting up to ``timeout`` seconds (None: none came)."""
        with self._cond:
            self._cond.wait_for(lambda: self._stop or (self._latest is not None and self._latest.seq > seq),
                                timeout=timeout)
            f = self._latest
        return f if f is not None and f.seq > seq else None

    def close(self) -> None:
        with self._cond:
            self._stop = True
            self._cond.notify_all()
        self._thread.join(timeout=5)

    def _run(self) -> None:
        seq = 0
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._stop or self._watchers > 0)
                if self._stop:
                    return
            started = time.perf_counter()
            try:
                image = self.holder.grab()
                self.error = None
            except RangekitError as exc:       # the device's own one-line error, shown on the page
                self.error, image = str(exc), None
            except Exception as exc:  # noqa: BLE001 - the stream goes on; the page and the log say why
                LOGGER.exception("live stream: a frame failed")
                self.error, image = f"the camera's frame failed: {type(exc).__name__}: {exc}", None
            if image is not None:
                seq += 1
                frame = live_frame(image, self.holder.full_scale, seq)
                annotate = self.annotate
                if annotate is not None:
                    try:
                        frame = replace(frame, extra=annotate(image))
                    except Exception:  # noqa: BLE001 - a guide drawn on the picture; the frame goes out without it
                        LOGGER.exception("live stream: annotating a frame failed")
                with self._cond:
                    self._latest = frame
                    self._cond.notify_all()
            time.sleep(max(0.0, self.period - (time.perf_counter() - started)) if image is not None else 0.2)
