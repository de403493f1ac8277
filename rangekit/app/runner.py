"""The job runner: it owns a job's concurrency, so the stages do not (issue 49).

A stage (:mod:`rangekit.app.process.decode`, ``register``, ``fuse``, ``evaluate``, the report's writer) takes a
typed input and returns a typed output; it does not time itself, announce itself, start a thread or a process,
or manage memory. The runner does: it times each stage and announces it on the job's event bus
(:class:`rangekit.app.bus.EventBus`, its own thread), runs a call beside another, maps a call over the views,
and returns freed memory between stages.

Where each piece of work runs is the placement table, :data:`PLACEMENTS`: one plan, three placements of it.

    ============== =============== ===================================== ========================
    work           LOCAL           STREAMING (a scan)                    DASK (a batch)
                   rangekit process                                      rangekit process S1 S2
    ============== =============== ===================================== ========================
    view decode    threads         the streaming worker as views come    a task per view, in memo
    pair refine    threads         ahead as views come, then threads     a task per pair
    truth prepare  a thread        ahead as views come, then a thread    a thread
    poisson        a child         a child                               a thread (1 core/worker)
    tsdf           a thread        a thread                              a thread
    closing        a thread        a thread                              a thread
    agreement      a thread        a thread                              a thread
    report panels  threads         threads                               threads
    ============== =============== ===================================== ========================

The STREAMING placement's live part is :class:`StreamingWorker`: as the scan's events announce views it runs the
scan's per-view steps (:class:`rangekit.app.scan.streaming.StreamingViews`: decode, place, integrate, the
registration and the truth ahead; no thread of their own) on a queue worker at a lower priority than the capture
(:class:`rangekit._runtime.queue_worker.QueueWorker`), held back while the capture is behind; the last view, which
the scan waits for, is left to the scan's own thread.

What the streaming placement or Dask did ahead reaches the runner in a :class:`Memo` (decoded views, the
registration's levels and first pairs, the prepared evaluator; Dask's decoded views are read from the view caches
its tasks wrote as they are taken), taken only where it is exactly what the stage would compute: the outputs are
the same bytes in every placement. The decode stage has one path in all three: each view from the memo, else
decoded on the runner's threads (LOCAL: every view; STREAMING: those the scan did not get to; DASK: none).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from enum import Enum
from typing import TYPE_CHECKING, Any

from rangekit._runtime.executor import Where, ordered_map, start
from rangekit._runtime.memory import adopt_kept, release_free_memory, reuse_freed_memory
from rangekit._runtime.queue_worker import QueueWorker
from rangekit._runtime.threads import one_blas_thread
from rangekit.app.bus import EventBus
from rangekit.app.events import CaptureLoad, Progress, Stage, StageClock, ViewAcquired

if TYPE_CHECKING:
    from rangekit.registration.ahead import RegistrationAhead

__all__ = ["Plan", "Work", "PLACEMENTS", "Memo", "Runner", "StreamingWorker", "STREAMING_NICE"]


class Plan(str, Enum):
    """The three placements of the one plan (:data:`PLACEMENTS`)."""

    LOCAL = "local"          # rangekit process: one process, its threads and a child
    STREAMING = "streaming"  # rangekit scan: views processed as they are acquired, the rest as LOCAL
    DASK = "dask"            # several sessions: tasks on a Dask cluster, each session's last part one task


class Work(str, Enum):
    """The pieces of a job that can run elsewhere than the job's thread."""

    VIEW_DECODE = "view decode"
    PAIR_REFINE = "pair refine"
    TRUTH_PREPARE = "truth prepare"
    POISSON = "poisson"
    TSDF = "tsdf"
    CLOSING = "closing"
    AGREEMENT = "agreement"
    REPORT_PANELS = "report panels"


_T, _C, _D = Where.THREAD, Where.CHILD, Where.DASK
#: Which work runs where, per plan (the module doc's table). A STREAMING view or pair done ahead comes in the
#: :class:`Memo`; what is left runs as shown.
PLACEMENTS: dict[Work, dict[Plan, Where]] = {
    Work.VIEW_DECODE: {Plan.LOCAL: _T, Plan.STREAMING: _T, Plan.DASK: _D},
    Work.PAIR_REFINE: {Plan.LOCAL: _T, Plan.STREAMING: _T, Plan.DASK: _D},
    Work.TRUTH_PREPARE: {Plan.LOCAL: _T, Plan.STREAMING: _T, Plan.DASK: _T},
    Work.POISSON: {Plan.LOCAL: _C, Plan.STREAMING: _C, Plan.DASK: _T},
    Work.TSDF: {Plan.LOCAL: _T, Plan.STREAMING: _T, Plan.DASK: _T},
    Work.CLOSING: {Plan.LOCAL: _T, Plan.STREAMING: _T, Plan.DASK: _T},
    Work.AGREEMENT: {Plan.LOCAL: _T, Plan.STREAMING: _T, Plan.DASK: _T},
    Work.REPORT_PANELS: {Plan.LOCAL: _T, Plan.STREAMING: _T, Plan.DASK: _T},
}


@dataclass(eq=False)
class Memo:
    """What was computed ahead of the stages, by the scan's live processing (STREAMING:
    :class:`StreamingWorker`) or by Dask's view tasks (DASK): ``decoded`` each view decoded (index ->
    ``(cloud, ViewMaps)``, its frames checked when read; taken out with ``pop`` as it is used, so its maps are
    freed with the others'; DASK's is :class:`rangekit.app.process.view_cache.ViewCaches`, which reads each view
    from the cache its task wrote as it is taken), ``announced`` whether those views were announced as
    :class:`~rangekit.app.events.ViewDecoded` when they were decoded (a Dask view task announces nothing: the
    decode stage does as it takes them), ``registration`` the registration's levels and first-round pairs
    (:class:`rangekit.registration.ahead.RegistrationAhead`), ``evaluate`` the evaluator with the truth's samples
    and the views' errors made, ``before_mesh`` called and waited for before the observed mesh is announced (a
    preview written beside the processing: a watcher has the preview first, issue 51; mesh.ply is written before
    it, whatever it takes; the scan now writes its preview before the processing and sets none),
    ``truth_after_mesh`` whether the views and the observed mesh are measured against the truth once mesh.ply and the closed mesh are written rather than beside Poisson and the closing (a scan: a
    person waits for the mesh, the simulator-only measures took a core from Poisson, and run beside the closing
    they were the one concurrency of the closed mesh's path the work ahead added, issue 51; the figures are the
    same), ``free`` each view's free depth (index
    -> (H, W) float32, the closed mesh's carving, :func:`rangekit.app.process.decode.free_depth_of`) made from its
    maps as it was decoded, ``blocks`` the blocks fusion's volume filled as the views came
(:class:`rangekit.app.process.blocks.BlocksAhead`). LOCAL's is empty: every view is decoded on the runner's
threads."""

    decoded: Any = field(default_factory=dict)   # a dict, or any mapping with ``in`` and ``pop``
    registration: RegistrationAhead | None = None
    evaluate: Any = None
    announced: bool = True
    before_mesh: Callable[[], Any] | None = None
    truth_after_mesh: bool = False
    free: dict = field(default_factory=dict)
    blocks: Any = None   # the blocks fusion's volume filled as the views came (app/process/blocks.BlocksAhead)


class Runner:
    """One job's runner (module doc): ``plan`` (:class:`Plan`) places its work, ``on_event`` is its subscriber
    (an :class:`EventBus` given is used as it is; anything else gets a bus of its own, closed by :meth:`close`),
    ``memo`` what was done ahead."""

    def __init__(self, on_event: Callable | None = None, *, plan: Plan = Plan.LOCAL, memo: Memo | None = None) -> None:
        self.plan = plan
        self.memo = memo if memo is not None else Memo()
        self._own_bus = not isinstance(on_event, EventBus)
        self.bus: EventBus = EventBus(on_event) if self._own_bus else on_event
        self._clock = StageClock(None if self.bus.quiet else self.bus)

    # ------------------------------------------------------------ events
    def emit(self, event) -> None:
        """Publish ``event`` on the job's bus."""
        if not self.bus.quiet:
            self.bus.publish(event)

    @property
    def progress(self) -> Callable | None:
        """``progress(msg, done=None, total=None)`` as :class:`Progress` events (None without a subscriber: the
        library's long functions then say nothing)."""
        if self.bus.quiet:
            return None

        def progress(msg: str, done: int | None = None, total: int | None = None) -> None:
            self.bus.publish(Progress(msg, done, total))

        return progress

    def say(self, msg: str, done: int | None = None, total: int | None = None) -> None:
        """One progress line (nothing without a subscriber)."""
        if not self.bus.quiet:
            self.bus.publish(Progress(msg, done, total))

    def close(self) -> None:
        """Hand on every event published (its own bus: ended)."""
        if self._own_bus:
            self.bus.close()
        else:
            self.bus.flush()

    # ------------------------------------------------------------ stages
    @property
    def seconds(self) -> dict[str, float]:
        """Wall seconds of each stage, in the order they started (a stage run in parts adds up)."""
        return self._clock.seconds

    @contextmanager
    def stage(self, stage: Stage, *, reuse_memory: bool = False, release_after: bool = False) -> Iterator[None]:
        """Time ``stage`` and announce it (StageStarted, StageFinished); ``reuse_memory``: freed arrays reused
        inside (:func:`rangekit._runtime.memory.reuse_freed_memory`), ``release_after``: free pages returned as it
        ends."""
        with self._clock.stage(stage):
            if reuse_memory:
                with reuse_freed_memory():
                    yield
            else:
                yield
            if release_after:
                release_free_memory()

    @staticmethod
    def release_memory() -> None:
        """Return the pages a stage just freed (:func:`rangekit._runtime.memory.release_free_memory`)."""
        release_free_memory()

    @staticmethod
    @contextmanager
    def memory_reused() -> Iterator[None]:
        """Inside, freed arrays are reused (:func:`rangekit._runtime.memory.reuse_freed_memory`)."""
        with reuse_freed_memory():
            yield

    # ------------------------------------------------------------ placement
    def where(self, work: Work) -> Where:
        return PLACEMENTS[work][self.plan]

    def beside(self, work: Work, fn: Callable, *args, where: Where | None = None, child=None, **kwargs):
        """Start ``fn(*args, **kwargs)`` where the table places ``work`` (or ``where``), beside this thread; use as
        ``with runner.beside(...) as call: ...; call.result()``."""
        return start(where or self.where(work), fn, *args, child=child, **kwargs)

    def map_views(self, fn: Callable, items: Iterable, *, each: Callable | None = None) -> Iterator:
        """``fn`` of each item in order, on the configured number of worker threads
        (:func:`rangekit._runtime.executor.ordered_map`; ``each(n)``: the context each call runs in)."""
        return ordered_map(fn, items, name="rangekit-views", each=each)

    def map_ordered(self, fn: Callable, items: Iterable) -> list:
        """``[fn(item) for item in items]`` on the configured number of worker threads, in order (the report's
        panels: each makes its own pictures)."""
        return list(ordered_map(fn, items, name="rangekit-report"))

    def pair_mapper(self):
        """The registration's pair mapper where the table places pair refinement (None: threads, in
        :func:`rangekit.registration.multiview.register_views`)."""
        if self.where(Work.PAIR_REFINE) is Where.DASK:
            from rangekit.app.batch.pairs import dask_pair_mapper

            return dask_pair_mapper()
        return None


#: How much lower the streaming worker's priority is than the capture's (its niceness; Linux: per thread).
STREAMING_NICE = 10


class StreamingWorker:
    """The STREAMING placement's live part: the scan's views, each through ``steps.view(k)`` as the scan's events
    bring them (``steps.views_of(event)``), on a worker thread of its own
    (:class:`rangekit._runtime.queue_worker.QueueWorker`) at niceness :data:`STREAMING_NICE` and one BLAS thread,
    so the capture's threads get the cores whenever they need them and the steps take what they leave. It backs
    off: while the capture is behind (the frames waiting to be written reached the writer's limit,
    :class:`~rangekit.app.events.CaptureLoad`) no new view is started; it starts again when they have drained to
    half, or when the acquisition ends (:meth:`drain`). From the last view's
    :class:`~rangekit.app.events.ViewAcquired` on it starts none
    (:meth:`rangekit._runtime.queue_worker.QueueWorker.hand_over`): that view, and any queued behind the one it is
    on, are decoded by :meth:`drain` on the scan's thread, at its priority and on every core. ``steps``: the
    per-view steps (:class:`rangekit.app.scan.streaming.StreamingViews`). Use :meth:`on_event` as a subscriber of
    the scan's events, then :meth:`drain`, :meth:`write_preview` and :meth:`finish_blocks` (or :meth:`finish`, all
    three), or :meth:`stop` on an error; :meth:`memo` hands on what was done to the processing."""

    def __init__(self, steps) -> None:
        self.steps = steps
        self._thread: int | None = None   # the thread that ran the last view's steps
        # one memory-reuse block from the first view to the last, those drain() hands to the caller included: each
        # view's frame stack and temporaries reuse the pages of the view before (the last view's decode 0.74 ->
        # 0.65 CPU-s under load, issue 51); while the queue is empty the steps read the last view's frames ahead
        # (StreamingViews.prefetch)
        self._worker = QueueWorker(self._one, name="rangekit-streaming", nice=STREAMING_NICE,
                                   context=reuse_freed_memory, idle=getattr(steps, "prefetch", None))

    def on_event(self, event) -> None:
        """A subscriber of the scan's events: queues the views an event brings; a :class:`CaptureLoad` holds the
        worker back (``behind``) or lets it go."""
        if isinstance(event, CaptureLoad):
            (self._worker.hold if event.behind else self._worker.release)()
        if isinstance(event, ViewAcquired) and event.index == event.total - 1:
            # the last view: the scan waits for it, so it and any view not yet started are decoded on the scan's
            # thread at its priority (drain), never started here at niceness 10, and the view being decoded here
            # leaves the rest of its steps to the scan too (issue 51: the preview)
            self.steps.acquisition_over = True
            self._worker.hand_over()
        for k in self.steps.views_of(event):
            self._worker.put(k)

    @property
    def paused(self) -> int:
        """Views that waited for the capture to catch up."""
        return self._worker.paused

    @property
    def error(self) -> BaseException | None:
        """The error that stopped the steps (the processing decodes the views left and meets it), or None."""
        return self._worker.error

    def drain(self) -> None:
        """The acquisition is over: the worker ends after the view it is on and the views queued go through their
        steps at once, on the caller's thread at its priority (each on every core;
        :meth:`rangekit._runtime.queue_worker.QueueWorker.finish`)."""
        self.steps.acquisition_over = True
        self._worker.finish()

    def write_preview(self):
        """After :meth:`drain`: the steps' preview (its path), or None when the steps failed (:attr:`error`)."""
        return None if self.error is not None else self.steps.write_preview()

    def finish_blocks(self) -> None:
        """After :meth:`write_preview`: the blocks fusion's volume finished (the steps' ``finish_blocks``), unless
        the steps failed (the processing then fills its own volume)."""
        if self.error is None:
            self.steps.finish_blocks()

    def finish(self):
        """:meth:`drain`, then :meth:`write_preview` (its answer) and :meth:`finish_blocks`."""
        self.drain()
        preview = self.write_preview()
        self.finish_blocks()
        return preview

    def stop(self) -> None:
        """Stop after the view going through its steps (its cache is complete or not written); the queued ones
        are left to the resumed scan or ``rangekit process``."""
        self._worker.stop()

    def memo(self) -> Memo:
        """What the steps did ahead, for the processing: each view decoded, the registration's levels and first
        pairs, the prepared evaluator (the last views' work ahead done here first, on the caller's thread: the scan
        calls this after :meth:`write_preview`)."""
        self.steps.last_ahead()
        return Memo(self.steps.results, self.steps.registration, self.steps.evaluate, truth_after_mesh=True,
                    free=self.steps.free, blocks=getattr(self.steps, "blocks", None))

    def _one(self, k: int) -> None:
        me = threading.get_ident()
        if self._thread is not None and self._thread != me:   # drain(): the caller takes over the worker's arrays
            adopt_kept(self._thread)
        self._thread = me
        with one_blas_thread():   # thin products (rangekit._runtime.threads)
            self.steps.view(k)
