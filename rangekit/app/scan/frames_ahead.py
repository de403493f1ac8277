"""A view's frames read while it is taken (issue 51: the preview within 1 s of the last frame): the scan's streaming
steps read the last view's frames from its ``.partial`` folder as the capture writes them
(:meth:`rangekit.app.scan.streaming.StreamingViews.prefetch`), checksummed and decoded into the view's stack, so that
once its last frame is written only the rest are read (:func:`rangekit.formats.sessions.check.read_view_stack`'s
``have``: a frame read ahead that is not the one recorded, a view taken again, is read again; the same pixels).
A frame file is complete once it has its name (the capture writes each to a temporary file and renames it).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

__all__ = ["FramesAhead"]


class FramesAhead:
    """The frames of view ``view`` read ahead from ``folder`` (its ``.partial`` folder while it is taken), in frame
    order, into one (``count``, H, W) stack (the thread's kept one, :func:`rangekit._runtime.memory.reused_array`):
    :meth:`read` reads the next frames written since, :meth:`have` hands them on
    (:func:`rangekit.formats.sessions.check.read_view_stack`'s ``have``)."""

    def __init__(self, view: int, folder: Path, count: int) -> None:
        self.view, self.folder, self.count = view, folder, count
        self.stack: np.ndarray | None = None
        self.sha256: dict[str, str] = {}

    def read(self) -> None:
        """Read the frames written since the last call, as long as they follow on in frame order (a frame
        written out of order waits for the one before it)."""
        from rangekit._runtime.memory import reused_array
        from rangekit.formats.capture import IMAGE_SUFFIXES, stack_from_bytes
        from rangekit.formats.sessions.check import frame_sha256
        from rangekit.regular_files import read_regular_file

        try:
            names = {p.name.split(".", 1)[0]: p for p in self.folder.iterdir()
                     if not p.name.startswith(".") and p.suffix.lower() in IMAGE_SUFFIXES}
        except OSError:   # not made yet, or renamed as the view is finished
            return
        while len(self.sha256) < self.count:
            i = len(self.sha256)
            path = names.get(f"{i:03d}")
            if path is None:
                return
            data = read_regular_file(path, what="a frame")
            digest = frame_sha256(data)

            def into(shape, dtype, i=i):
                if self.stack is None:
                    self.stack = reused_array("frames0", (self.count, *shape[1:]), dtype)
                return self.stack[i:i + 1]

            stack_from_bytes([path], [data], workers=1, empty=into)
            self.sha256[path.name] = digest

    def have(self) -> tuple[np.ndarray, dict] | None:
        """``(stack, {frame file name: SHA-256})`` of the frames read, or None (none)."""
        return None if self.stack is None or not self.sha256 else (self.stack, dict(self.sha256))
