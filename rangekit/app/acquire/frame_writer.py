"""A scan's frames rendered, encoded and written behind the capture, on both cores.

:func:`rangekit.app.acquire.acquire.acquire` takes every frame in order on its own thread (pattern shown, then
the camera's frame) and hands each one here as a function that returns the image: a real camera's image
already taken, or a simulated frame still to render (``SimCamera.capture_deferred``: the frame's noise,
pattern and exposure fixed when it was taken, so its bytes do not depend on where it renders). Up to
``workers`` threads turn them into frame files (render, encoding (``.npy.zst`` or PNG) and the atomic, fsynced write
release the GIL) while the next frames are taken, and the next view's turntable move and ray cast run.

At most ``max_pending`` frames wait (a waiting simulated frame holds no image, a real one its image), so
memory stays flat. When they reach it the capture is behind (it waits for the writer): ``on_load(True, pending)``
says so, and ``on_load(False, pending)`` once half of them are written (the scan announces both as
:class:`rangekit.app.events.CaptureLoad`; processing during the scan backs off in between). A view is finished (``finish(sha256)``: view.json, the rename, session.json) by one
finishing thread, in view order, only after every one of its frames is on disk, and not after a view
that failed: the crash safety of :mod:`rangekit.app.acquire.acquire` is unchanged (a failure in one view leaves
the views before it finished). The failure (a write, a render) earliest in capture order is kept as a
:class:`FrameError` naming the view and the step (the same one whichever thread fails first: frames
after it are skipped, frames before it still written), raised by the next :meth:`FrameWriter.check`;
:meth:`FrameWriter.close` waits for the work handed over (the views whose frames were all taken are
finished, also after an error elsewhere or Ctrl-C) and raises it.
"""

from __future__ import annotations

import threading
from concurrent.futures import Future, ThreadPoolExecutor, wait
from pathlib import Path
from typing import Callable

from rangekit._runtime.executor import worker_count
from rangekit.formats.sessions.check import frame_sha256
from rangekit.io import write_frame

__all__ = ["FrameError", "FrameWriter"]


class FrameError(Exception):
    """A frame or view that failed behind the capture: ``view`` (index), ``angle`` (radians), ``step`` (the
    same words acquisition uses: ``frame 3 (x_bit03): writing``), ``target`` (the file or folder) and the
    original exception ``error``; ``order`` its place in capture order (frames numbered from 0, a view's
    finishing after its frames); ``device`` the device acquisition was calling ("turntable", "projector",
    "lasers", "camera"), None for a failure behind the capture."""

    def __init__(self, view: int, angle: float, step: str, target: Path, error: BaseException,
                 order: float = float("inf"), device: str | None = None) -> None:
        super().__init__(f"view {view}, {step}: {error}")
        self.view, self.angle, self.step, self.target, self.error = view, angle, step, target, error
        self.order, self.device = order, device


class FrameWriter:
    """Write frames on ``workers`` threads; finish views in order on one more (see the module docstring)."""

    def __init__(self, *, workers: int = 0, max_pending: int = 64,
                 on_load: Callable[[bool, int], None] | None = None) -> None:
        self._pool = ThreadPoolExecutor(max_workers=worker_count(workers), thread_name_prefix="rangekit-frames")
        self._finisher = ThreadPoolExecutor(max_workers=1, thread_name_prefix="rangekit-views")
        self._slots = threading.BoundedSemaphore(max_pending)
        self._frames: list[tuple[str, Future]] = []      # the view being taken: (file key, future of its SHA-256)
        self._views: list[Future] = []
        self._error: FrameError | None = None          # the failure earliest in capture order
        self._order = 0                                   # frames handed over so far
        self._broken = False                              # a view failed: the later ones are not finished
        self._lock = threading.Lock()
        self._max_pending, self._pending, self._behind, self._on_load = max_pending, 0, False, on_load

    def _fail(self, error: FrameError) -> None:
        with self._lock:
            if self._error is None or error.order < self._error.order:
                self._error = error

    @property
    def error(self) -> FrameError | None:
        """The failure earliest in capture order so far (after :meth:`close`: of all the work), or None."""
        return self._error

    def check(self) -> None:
        """Raise the earliest failure behind the capture, if any."""
        if self._error is not None:
            raise self._error

    def frame(self, view: int, angle: float, key: str, name: str, target: Path, image: Callable) -> None:
        """Queue frame ``key`` (its file relative to the view folder; ``name`` the step's words, e.g.
        ``frame 3 (x_bit03)``) of ``view``: ``image()`` gives the image, written to ``target``. Blocks
        while ``max_pending`` frames wait; raises an earlier failure first."""
        self.check()
        if not self._slots.acquire(blocking=False):    # the writer is max_pending frames behind: say so, then wait
            self._load(True)
            self._slots.acquire()
        with self._lock:
            self._pending += 1
        try:
            self.check()
        except BaseException:
            self._release()
            raise
        order, self._order = self._order, self._order + 1
        self._frames.append((key, self._pool.submit(self._write, view, angle, name, target, image, order)))

    def _write(self, view: int, angle: float, name: str, target: Path, image: Callable, order: int) -> str:
        try:
            failed = self._error
            if failed is not None and failed.order < order:     # an earlier frame failed: skip this one
                raise FrameError(view, angle, f"{name}: skipped", target, RuntimeError("an earlier frame failed"))
            step = f"{name}: camera"
            try:
                img = image()
                step = f"{name}: writing"
                return frame_sha256(write_frame(target, img))
            except Exception as exc:
                error = FrameError(view, angle, step, target, exc, order)
                self._fail(error)
                raise error from exc
        finally:
            self._release()

    def _release(self) -> None:
        """A frame's slot given back (written, failed or cancelled); the capture caught up at half the limit."""
        with self._lock:
            self._pending -= 1
        self._slots.release()
        if self._behind and self._pending <= self._max_pending // 2:
            self._load(False)

    def _load(self, behind: bool) -> None:
        """``on_load(behind, pending)`` when the state changes (once each way)."""
        with self._lock:
            if self._behind == behind:
                return
            self._behind = behind
            pending = self._pending
        if self._on_load is not None:
            self._on_load(behind, pending)

    def finish_view(self, view: int, angle: float, target: Path, finish: Callable[[dict], None]) -> None:
        """Once every frame queued since the last call is on disk, call ``finish(sha256)`` (file key ->
        SHA-256 hex, in frame order) on the finishing thread, after the views before."""
        frames, self._frames = self._frames, []
        order = self._order - 0.5                         # after the view's frames, before the next view's
        self._views.append(self._finisher.submit(self._finish, view, angle, target, frames, finish, order))

    def _finish(self, view: int, angle: float, target: Path, frames, finish: Callable[[dict], None],
                order: float) -> None:
        sha256 = {}
        for key, future in frames:
            try:
                sha256[key] = future.result()
            except FrameError:                # kept by _fail: this view and the later ones are not finished
                self._broken = True
        if self._broken:
            return
        try:
            finish(sha256)
        except FrameError as exc:
            self._broken = True
            exc.order = order
            self._fail(exc)
        except Exception as exc:
            self._broken = True
            self._fail(FrameError(view, angle, "finishing the view", target, exc, order))

    def drop_view(self) -> None:
        """Forget the view being taken (it is to be taken again): its frames not started are cancelled, those
        being written are waited for, so nothing of it is written afterwards."""
        frames, self._frames = self._frames, []
        for _, future in frames:
            if future.cancel():
                self._release()           # the slot its _write would have released
        wait([future for _, future in frames])

    def cancel_view(self) -> None:
        """Drop the frames of the view being taken that have not started (its view is not finished)."""
        for _, future in self._frames:
            future.cancel()
        self._frames = []

    def close(self, *, raise_error: bool = True) -> None:
        """Wait for every frame and view handed over, then raise the first failure (``raise_error``)."""
        self._pool.shutdown(wait=True)
        self._finisher.shutdown(wait=True)
        if raise_error:
            self.check()
