"""What a running job tells its subscribers: typed events, one frozen dataclass each.

A job (:func:`rangekit.app.scan.scan.scan`, :func:`rangekit.app.process.process.process_session`) takes
``on_event``, a callable given every event in the order things happen, one at a time, on the thread of the
job's event bus (:class:`rangekit.app.bus.EventBus`): never on the capture's or the frame writer's. The
command line's progress bar is one subscriber (:func:`progress_subscriber`); a web view or a notebook is
another. A subscriber that raises stops the job with its exception (nothing is swallowed).

Units as everywhere in rangekit: metres, radians, seconds.
"""

from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import dataclass
from enum import Enum
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Iterator, Union

from rangekit.progress import StageTimer

if TYPE_CHECKING:
    from rangekit.surface.cloud import PointCloud
    from rangekit.surface.mesh import TriangleMesh

__all__ = ["StageStarted", "StageFinished", "Progress", "ScanStarted", "FramesWritten", "ViewAcquired", "CaptureLoad",
           "ViewDecoded", "ViewPlaced", "PairRegistered", "MeshStarted", "MeshReady", "JobFailed", "Event", "OnEvent",
           "emit", "progress_of", "progress_subscriber"]


class Stage(str, Enum):
    """The stages of a job, as its events and summary.json's ``seconds`` name them (a ``str``: ``Stage.DECODE ==
    "decode"``). A coded-light session is decoded, registered, fused, evaluated and reported; a laser session's
    profiles take the place of the first two."""

    ACQUIRE = "acquire"
    DECODE = "decode"
    REGISTER = "register"
    PROFILES = "profiles"
    FUSE = "fuse"
    EVALUATE = "evaluate"
    REPORT = "report"

    def __str__(self) -> str:
        return self.value


@dataclass(frozen=True)
class StageStarted:
    """A stage began (:class:`Stage`)."""

    stage: Stage


@dataclass(frozen=True)
class StageFinished:
    """A stage ended after ``seconds`` of wall time (a stage run in parts, such as ``"evaluate"`` beside the
    fusion and after it, finishes once per part)."""

    stage: Stage
    seconds: float


@dataclass(frozen=True)
class Progress:
    """A line for people: ``message``, with ``done`` of ``total`` steps when the work is counted."""

    message: str
    done: int | None = None
    total: int | None = None


@dataclass(frozen=True)
class ScanStarted:
    """A scan is set up and about to acquire into ``folder``: ``total`` turntable views (a laser scan's steps)
    of ``n_frames`` frames each (at each exposure of ``exposures_us``, None: the rig's one exposure),
    ``done`` of them already on disk (``resume``)."""

    folder: Path
    total: int
    done: int
    n_frames: int
    resume: bool
    exposures_us: tuple[int, ...] | None
    laser: bool


@dataclass(frozen=True)
class FramesWritten:
    """Every frame of view ``index`` (0-based, of ``total``) is on disk, ``n_frames`` of them: its last frame was
    just written; the view is finished next (view.json, its folder renamed, session.json: :class:`ViewAcquired`)."""

    index: int
    total: int
    n_frames: int


@dataclass(frozen=True)
class ViewAcquired:
    """View ``index`` (0-based, of ``total``) is on disk: its folder, frames and turntable angle (radians)."""

    index: int
    total: int
    folder: Path
    angle: float
    n_frames: int


@dataclass(frozen=True)
class CaptureLoad:
    """The capture's backlog: ``behind`` True when the frames waiting to be written reached the frame writer's
    limit (``pending`` of them: the capture waits for them), False when they drained to half of it. Processing
    that runs during the scan (:mod:`rangekit.app.scan.streaming`) pauses between views while the capture is
    behind."""

    behind: bool
    pending: int


@dataclass(frozen=True, eq=False)
class ViewDecoded:
    """View ``index`` (0-based, of ``total``) decoded: its filtered cloud, in the session world at the view's own
    turntable angle (not yet registered)."""

    index: int
    total: int
    name: str
    cloud: PointCloud


@dataclass(frozen=True, eq=False)
class ViewPlaced:
    """During a scan (:mod:`rangekit.app.scan.streaming`), view ``index`` placed beside the views already in:
    ``cloud`` (session world at the view's turntable angle, as in :class:`ViewDecoded`) and ``T_world_view``
    (4, 4), its pose in the first view's frame (the turntable prior refined against its neighbour): the
    growing model, before the processing's closing registration."""

    index: int
    total: int
    name: str
    cloud: PointCloud
    T_world_view: object


@dataclass(frozen=True)
class PairRegistered:
    """One view pair's refinement: ``rmse`` (metres), ``overlap`` (fraction), accepted or refused (``reason``)."""

    i: int
    j: int
    rmse: float
    overlap: float
    accepted: bool
    reason: str


@dataclass(frozen=True)
class MeshStarted:
    """The mesh ``kind`` (as :class:`MeshReady`'s) is being made: for ``"preview"``, the streaming volume's surface
    extracted and written, the scan's final view placed and integrated just before (its :class:`ViewPlaced`;
    :mod:`rangekit.app.scan.streaming`)."""

    kind: str


@dataclass(frozen=True, eq=False)
class MeshReady:
    """A mesh file was written: ``kind`` ``"observed"`` (mesh.ply), ``"watertight"`` (mesh_watertight.ply) or
    ``"preview"`` (preview.ply: a scan's views fused as they were decoded, :mod:`rangekit.app.scan.streaming`)."""

    kind: str
    path: Path
    mesh: TriangleMesh


@dataclass(frozen=True, eq=False)
class JobFailed:
    """The job stops with ``error`` (raised to the caller right after this event)."""

    error: BaseException


Event = Union[StageStarted, StageFinished, Progress, ScanStarted, FramesWritten, ViewAcquired, CaptureLoad, ViewDecoded,
              ViewPlaced, PairRegistered, MeshStarted, MeshReady, JobFailed]
#: A subscriber: called with each event.
OnEvent = Callable[[Event], None]


def emit(on_event: OnEvent | None, event: Event) -> None:
    """Hand ``event`` to the subscriber, if there is one."""
    if on_event is not None:
        on_event(event)


def progress_of(on_event: OnEvent | None) -> Callable | None:
    """The ``progress(msg, done=None, total=None)`` callable the library's long functions take
    (:mod:`rangekit.progress`), as :class:`Progress` events to ``on_event``; None without a subscriber."""
    if on_event is None:
        return None

    def progress(msg: str, done: int | None = None, total: int | None = None) -> None:
        on_event(Progress(msg, done, total))

    return progress


def progress_subscriber(progress: Callable | None) -> OnEvent | None:
    """A subscriber that shows the :class:`Progress` events with ``progress(msg, done, total)`` (the command
    line's :class:`rangekit.progress.Console`) and ignores the others; None for None."""
    if progress is None:
        return None

    def on_event(event: Event) -> None:
        if isinstance(event, Progress):
            progress(event.message, event.done, event.total)

    return on_event


@contextmanager
def failures_announced(on_event: OnEvent | None) -> Iterator[None]:
    """Any exception inside is handed to ``on_event`` as :class:`JobFailed`, then raised on."""
    try:
        yield
    except BaseException as exc:
        emit(on_event, JobFailed(exc))
        raise


class StageClock(StageTimer):
    """:class:`rangekit.progress.StageTimer` (wall seconds per named stage) that also announces each part of a
    stage to ``on_event`` as :class:`StageStarted` and :class:`StageFinished`."""

    def __init__(self, on_event: OnEvent | None = None) -> None:
        super().__init__()
        self._on_event = on_event

    @contextmanager
    def stage(self, name: Stage | str) -> Iterator[None]:
        name = Stage(name)
        emit(self._on_event, StageStarted(name))
        t0 = time.perf_counter()
        with super().stage(name.value):
            yield
        emit(self._on_event, StageFinished(name, time.perf_counter() - t0))


__all__ += ["Stage", "StageClock", "failures_announced"]
