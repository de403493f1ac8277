"""Many sessions processed on Dask (``rangekit process S1 S2 ... [--scheduler local|ADDRESS] [--workers N]``).

The DASK placement of the job runner's plan (:data:`rangekit.app.runner.PLACEMENTS`). Each coded-light view's
decoding is one task (:func:`decode_view_task`): it checks the view's frames against their SHA-256s, then
decodes, triangulates and filters the view into its cache in the view folder
(:mod:`rangekit.app.process.view_cache`: ``cloud.json`` is written last and vouches for the rest). Then, per
session, one task (:func:`finish_session_task`) runs the processing (registration, fusion, evaluation on the
simulator, report) with those views in the runner's memo (:class:`rangekit.app.process.view_cache.ViewCaches`:
each read from its cache as the decode stage takes it, its frames checked); each view pair's registration within
it is a task of its own (:mod:`rangekit.app.batch.pairs`). Its outputs are the bytes of processing the session in
one process. A laser session is one task.

Tasks are idempotent through the cache: a task retried after its worker died, or a rerun of the whole
batch, reads what was finished and redoes only what was not. A worker holds one view's image stack at a
time (a view task returns the number of points, not the cloud). The session folders must be readable
and writable by every worker at the same path (one machine, or a shared file system on a cluster).

A session that fails (a bad ``session.json``, a missing or changed frame, ...) is recorded with its error
while the others finish (:class:`BatchResult`).
"""

from __future__ import annotations

import os
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

from rangekit._runtime.executor import worker_count
from rangekit.app.process.options import ProcessOptions
from rangekit.errors import ConfigError, RangekitError
from rangekit.progress import call_progress
from rangekit.formats.sessions.files import CLOUD_INFO_FILE, SESSION_FILE

__all__ = ["WORKER_ENV", "BatchResult", "SchedulerUnreachable", "SessionOutcome", "ViewDone", "decode_view_task",
           "finish_session_task", "process_sessions"]

#: Environment of each local worker process: one thread for numba, OpenMP and BLAS (the worker is the unit
#: of parallelism; give a cluster's workers the same, docs/scale.md).
WORKER_ENV = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}

#: glibc's malloc in each local worker process, set before it starts (glibc reads them then): one arena, and
#: arrays up to 1 GB from it, never trimmed back on free. A worker runs task after task of the same sizes;
#: so every task reuses the pages the one before freed instead of faulting fresh ones in (which the kernel
#: must zero), and :func:`rangekit._runtime.memory.release_free_memory` leaves them (with one arena every thread
#: reuses them). Replaces the nanny's MALLOC_TRIM_THRESHOLD_=65536, which made every large array a fresh
#: mmap. The batch of docs/scale.md: 170-174 against 198-203 CPU-s with glibc's defaults, peak of the tree
#: 3.5 GB either way (recorded at 0339c3a).
WORKER_MALLOC = {"MALLOC_ARENA_MAX": "1", "MALLOC_MMAP_THRESHOLD_": str(1 << 30), "MALLOC_TRIM_THRESHOLD_": str(1 << 30)}

#: Dask settings of the local cluster: its periodic housekeeping slowed down (the event loop's tick, the
#: system and memory monitors, work stealing) and the workers' statistical profiler off. Together they cost
#: an idle cluster of 2 workers 6.5-7.1 CPU-s every 100 s, against 1.1 with these
#: (benchmarks/app/bench_dask_idle.py): CPU taken from tasks that each run for seconds. Nothing here reads the
#: dashboard they feed.
QUIET_DASK = {"distributed.admin.tick.interval": "1s", "distributed.admin.system-monitor.interval": "5s",
              "distributed.scheduler.work-stealing-interval": "5s", "distributed.worker.memory.monitor-interval": "1s",
              "distributed.worker.profile.enabled": False}

#: Seconds to wait for a scheduler at an address before giving up.
CONNECT_TIMEOUT_S = 5.0


class SchedulerUnreachable(RangekitError):
    """No Dask scheduler answered at the address given (exit 1)."""


#: A Dask scheduler's first message (its handshake) is a few hundred bytes; a length beyond this is not Dask's.
MAX_HANDSHAKE_BYTES = 1 << 20


def probe_scheduler(address: str, timeout: float) -> None:
    """SchedulerUnreachable unless a Dask scheduler's handshake arrives from ``address`` (``tcp://HOST:PORT``)
    within ``timeout`` seconds. A Dask scheduler writes its handshake as soon as a connection opens: its first
    8 bytes are the message's length (little-endian), then the message. ``distributed.Client`` writes first and
    trusts that length: an HTTP server there (the dashboard's port) answered with 'HTTP/1.1 400', read as a
    length of 10^18 bytes, and the client never returned; a server sending garbage ended in 'out of memory'."""
    import socket
    import struct
    from urllib.parse import urlsplit

    expected = f"--scheduler {address}: expected a Dask scheduler (dask scheduler) answering there, found "
    try:
        parts = urlsplit(address)
        host, port = parts.hostname, parts.port
    except ValueError:
        host = port = None
    if parts.scheme != "tcp" or not host or port is None:
        raise SchedulerUnreachable(expected + "an address that is not tcp://HOST:PORT")
    deadline = time.monotonic() + timeout
    head, connected = b"", False
    try:
        with socket.create_connection((host, port), timeout=timeout) as sock:
            connected = True
            while len(head) < 8:
                sock.settimeout(max(deadline - time.monotonic(), 1e-3))
                chunk = sock.recv(8 - len(head))
                if not chunk:
                    raise SchedulerUnreachable(expected + f"a server that closed the connection after {len(head)} "
                                               "bytes, without Dask's handshake")
                head += chunk
    except (socket.timeout, TimeoutError):
        raise SchedulerUnreachable(expected + (f"a server that sent no Dask handshake within {timeout:g} s (another "
                                               "protocol there, such as the dashboard's HTTP port?)" if connected
                                               else f"none within {timeout:g} s")) from None
    except OSError as e:
        raise SchedulerUnreachable(expected + f"none within {timeout:g} s ({type(e).__name__}: "
                                   f"{e.strerror or e})") from None
    length = struct.unpack("<Q", head)[0]
    if not 0 < length <= MAX_HANDSHAKE_BYTES:
        raise SchedulerUnreachable(expected + f"a server that speaks another protocol (its first bytes {head!r})")


@dataclass(frozen=True)
class ViewDone:
    """A view task's result: the view folder's name, its points, whether this task decoded it (False: it was
    found in the cache), and its index in the session."""

    view: str
    points: int
    decoded: bool
    index: int


@dataclass(frozen=True)
class SessionOutcome:
    """One session of a batch: ``error`` None when it was processed (``summary`` holds the lines of its
    end-of-run summary), else the message of what failed (naming the file)."""

    folder: Path
    error: str | None = None
    summary: tuple[str, ...] = ()
    views_decoded: int = 0   # views decoded by this batch (the others came from the cache)
    views_cached: int = 0

    @property
    def ok(self) -> bool:
        return self.error is None


@dataclass(frozen=True)
class BatchResult:
    """Every session of :func:`process_sessions`, in the order given, and the batch's wall seconds."""

    sessions: tuple[SessionOutcome, ...]
    seconds: float

    @property
    def failed(self) -> tuple[SessionOutcome, ...]:
        return tuple(s for s in self.sessions if not s.ok)


def decode_view_task(folder: str, index: int, method: str = "auto", table_margin: float = 0.002,
                     max_motion: float | None = 0.02) -> ViewDone:
    """Decode view ``index`` of the session in ``folder`` into its cache (a Dask task; idempotent: a view
    already cached with these settings is only read back). Raises FileFormatError when the view's frames
    differ from their recorded SHA-256s."""
    from rangekit.app.process.view_cache import cache_settings, table_transform, view_cloud
    from rangekit.formats.sessions.session import Session
    from rangekit.formats.sessions.check import verify_views
    from rangekit._runtime.memory import release_free_memory

    session = Session.load(folder)
    view = next((v for v in session.done_views if v.index == index), None)
    if view is None:
        raise ConfigError(f"{Path(folder) / SESSION_FILE}: expected view {index} done, found it "
                          f"{'pending' if any(v.index == index for v in session.views) else 'missing'}")
    verify_views(session, views=[view], workers=1, contents=False)   # the contents as the frames are read
    stamp = _stamp(view.folder / CLOUD_INFO_FILE)
    cloud, _ = view_cloud(view, session.pattern, session.rig, cache_settings(session, method, table_margin, max_motion),
                          session.capture.full_scale, table_transform(session.rig), table_margin, session)
    done = ViewDone(view.folder.name, len(cloud), _stamp(view.folder / CLOUD_INFO_FILE) != stamp, index)
    del cloud
    release_free_memory()   # the view's stack and maps: a worker holds one view at a time
    return done


def _stamp(path: Path) -> tuple[int, int] | None:
    """A file's (inode, mtime ns): changes when it is written again (atomic writes replace the file)."""
    try:
        st = os.stat(path)
    except OSError:
        return None
    return st.st_ino, st.st_mtime_ns


def finish_session_task(folder: str, views: Sequence[ViewDone], options: ProcessOptions) -> tuple[str, ...]:
    """Register, fuse, evaluate (a simulated session, with ``options.truth``) and report the session in
    ``folder`` once its ``views`` are decoded (a Dask task; they come from their caches, through the runner's memo).
    Returns the end-of-run summary lines."""
    from rangekit.app.process.view_cache import ViewCaches
    from rangekit.app.runner import Memo, Plan
    from rangekit.app.scan.scan import process_placed

    # the Dask placement of the plan: the views its tasks decoded in the memo, each view pair's registration a
    # task of its own (PLACEMENTS, batch_pairs)
    decoded = ViewCaches(folder, [v.index for v in views], options.method, options.table_margin, options.max_motion)
    memo = Memo(decoded=decoded, announced=False)
    return tuple(process_placed(folder, options, plan=Plan.DASK, memo=memo).summary_lines())


def process_sessions(folders: Sequence[str | Path], options: ProcessOptions | None = None, *,
                     scheduler: str = "local", workers: int = 0, progress: Callable | None = None,
                     timeout: float = CONNECT_TIMEOUT_S) -> BatchResult:
    """Process every session folder on Dask; each into its ``mesh.ply`` etc. as
    :func:`rangekit.app.process.process.process_session` does (the same bytes).

    Parameters
    ----------
    options : how (:class:`ProcessOptions`; ``truth``: measure simulated sessions against their truth, as
        ``rangekit process`` does); the defaults if None.
    scheduler : "local" (a ``LocalCluster`` of ``workers`` processes on 127.0.0.1, one thread each; 0: the
        configured number, :func:`rangekit._runtime.executor.worker_count`) or the address of a running ``dask scheduler`` (``tcp://host:port``; ``workers`` is then unused).
    progress : ``progress(msg, done=None, total=None)``: a line per view and per session done or failed.
    timeout : seconds to wait for the scheduler at an address.

    Raises
    ------
    SchedulerUnreachable
        No scheduler answered at ``scheduler`` within ``timeout`` seconds. A session that fails does not
        raise: its :class:`SessionOutcome` holds the error.
    """
    options = options or ProcessOptions()
    if scheduler == "local" and not (isinstance(workers, int) and not isinstance(workers, bool) and workers >= 0):
        raise ConfigError(f"workers: expected a whole number >= 1 (0: the configured number), found {workers!r}")
    t0 = time.perf_counter()
    folders = [Path(f) for f in folders]
    outcome: dict[int, dict] = {k: {"folder": f} for k, f in enumerate(folders)}
    plans = []   # (k, view indices or None for a laser session)
    for k, f in enumerate(folders):
        try:
            plans.append((k, _view_indices(f)))
        except RangekitError as e:
            outcome[k]["error"] = str(e)
            call_progress(progress, f"{f}: failed: {e}")
    if plans:
        with _client(scheduler, workers, timeout) as client:
            _run(client, plans, folders, outcome, options, progress)
    return BatchResult(tuple(SessionOutcome(**o) for o in outcome.values()), time.perf_counter() - t0)


def _view_indices(folder: Path) -> list[int] | None:
    """The done views of a coded-light session (None: a laser session, processed in one task)."""
    from rangekit.formats.sessions.session import Session

    if not (folder / SESSION_FILE).is_file():
        raise ConfigError(f"{folder}: not a session folder (no {SESSION_FILE})")
    session = Session.load(folder)
    return None if session.is_laser else [v.index for v in session.done_views]


def _run(client, plans, folders, outcome, options, progress) -> None:
    """Submit every view task, then each group's session tasks once the group's views are done; report them
    as they finish.

    The sessions go in groups of as many as the cluster has threads. Every view task is submitted at once,
    earlier groups first (Dask runs the higher priority first); a group's session tasks are submitted
    when all its views are done, ahead of any view. So the long session tasks of a group start together,
    one a thread, and end together, while the next group's views wait: on 2 workers, 4 sessions finish in
    two rounds of two instead of one worker finishing the last session alone (docs/scale.md)."""
    from distributed import as_completed

    run = uuid.uuid4().hex[:8]
    owner = {}   # future key -> (session number, "view" | "session")
    slots = max(1, sum(client.nthreads().values()))
    groups = [plans[g: g + slots] for g in range(0, len(plans), slots)]
    group_of, views_of, left = {}, {}, []   # session -> group; session -> its view futures; views left a group
    for g, group in enumerate(groups):
        for k, indices in group:
            name = folders[k].name
            group_of[k] = g
            views_of[k] = [client.submit(decode_view_task, str(folders[k]), i, options.method, options.table_margin,
                                         options.max_motion, key=f"decode-{name}-{i:03d}-{k}-{run}",
                                         pure=False, priority=len(groups) - g) for i in indices or ()]
            owner.update({f.key: (k, "view") for f in views_of[k]})
        left.append(sum(len(views_of[k]) for k, _ in group))
    queue = as_completed([f for fs in views_of.values() for f in fs])

    def finish_group(g: int) -> None:
        for k, _ in groups[g]:
            session = client.submit(finish_session_task, str(folders[k]), views_of[k], options,
                                    key=f"session-{folders[k].name}-{k}-{run}", pure=False, priority=len(groups) + 1)
            owner[session.key] = (k, "session")
            queue.add(session)

    for g, n in enumerate(left):
        if n == 0:   # laser sessions only
            finish_group(g)
    views_done = sessions_done = 0
    n_views = sum(left)
    for fut in queue:
        k, kind = owner[fut.key]
        o, folder = outcome[k], folders[k]
        if kind == "view":
            views_done += 1
            left[group_of[k]] -= 1
            if fut.status == "error":
                o.setdefault("error", _message(fut.exception()))
            else:
                done = fut.result()
                key = "views_decoded" if done.decoded else "views_cached"
                o[key] = o.get(key, 0) + 1
                call_progress(progress, f"{folder}/{done.view}: {done.points:,} points"
                                        + ("" if done.decoded else " (from the cache)"), views_done, n_views)
            if left[group_of[k]] == 0:
                finish_group(group_of[k])
            continue
        sessions_done += 1
        if fut.status == "error":
            o.setdefault("error", _message(fut.exception()))
            call_progress(progress, f"{folder}: failed: {o['error']}", sessions_done, len(plans))
        else:
            o["summary"] = fut.result()
            call_progress(progress, f"{folder}: done ({sessions_done}/{len(plans)} sessions)", sessions_done,
                          len(plans))
        for f in (*views_of[k], fut):
            f.release()


def _message(e: BaseException) -> str:
    """A failed task's error as the summary shows it: a rangekit error's message (it names the file), else
    the exception's type too."""
    return str(e) if isinstance(e, RangekitError) else f"{type(e).__name__}: {e}"


class _client:
    """A ``distributed.Client`` on a new local cluster or at an address; closes both on exit."""

    def __init__(self, scheduler: str, workers: int, timeout: float):
        self.scheduler, self.workers, self.timeout = scheduler, workers, timeout
        self.cluster = None

    def __enter__(self):
        import logging

        from distributed import Client, LocalCluster

        if self.scheduler == "local":
            import dask

            # The workers inherit WORKER_MALLOC from this process's environment, set while they are spawned and
            # put back after: Dask's own way (its nanny's pre-spawn-environ) leaves it in this process for good,
            # and an earlier cluster's value there would win over the config. The nanny's default
            # MALLOC_TRIM_THRESHOLD_=65536 is dropped.
            saved = {k: os.environ.get(k) for k in WORKER_MALLOC}
            os.environ.update(WORKER_MALLOC)
            try:
                with dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None, **QUIET_DASK}):
                    self.cluster = LocalCluster(n_workers=worker_count(self.workers), threads_per_worker=1, processes=True,
                                                host="127.0.0.1", dashboard_address=None, env=dict(WORKER_ENV),
                                                silence_logs=logging.ERROR)
            finally:
                for k, v in saved.items():
                    if v is None:
                        os.environ.pop(k, None)
                    else:
                        os.environ[k] = v
            self.client = Client(self.cluster)
            return self.client
        probe_scheduler(self.scheduler, self.timeout)
        try:
            self.client = Client(self.scheduler, timeout=f"{self.timeout}s")
        except (OSError, TimeoutError, ValueError) as e:
            raise SchedulerUnreachable(
                f"--scheduler {self.scheduler}: expected a Dask scheduler (dask scheduler) answering there, "
                f"found none within {self.timeout:g} s ({type(e).__name__}: {e})") from None
        return self.client

    def __exit__(self, *exc) -> None:
        self.client.close()
        if self.cluster is not None:
            self.cluster.close()
