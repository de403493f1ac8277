"""The process's surroundings, checked before a command runs and consulted when it fails: the working
folder, numba's thread setting, the address-space limit, the output encoding, and Ctrl-C.

Only the standard library is imported here: :func:`prepare` runs before numpy, OpenCV or Open3D load.

- A working folder deleted under the shell, ``NUMBA_NUM_THREADS=0`` or ``abc``: numba fails deep inside an
  import; here they are named before anything loads (:func:`problems`).
- ``ulimit -v``: below about 0.6 GB of address space loading the libraries crashes with SIGSEGV, between
  0.6 and 3 GB they fail to map ("failed to map segment") or OpenCV cannot allocate an image. A limit
  below :data:`MIN_ADDRESS_SPACE` is refused up front; a failure under a lower limit than a full scan
  needs is told as a memory shortage naming the limit (:func:`memory_shortage`).
- ``PYTHONIOENCODING=ascii`` with a non-ASCII path: printing it would raise; the streams escape instead.
- Ctrl-C while a C extension initialises surfaces as ``ImportError: initialization failed`` (numpy), or is
  swallowed (Open3D's extension: the command ran to the end). :func:`interrupted` tells that a SIGINT
  arrived, so the command still ends with 130, and a swallowed one is raised again at the next import.
"""

from __future__ import annotations

import os
import signal
import sys
from contextlib import contextmanager

__all__ = ["MIN_ADDRESS_SPACE", "FULL_SCAN_ADDRESS_SPACE", "prepare", "problems", "interrupted", "watching_interrupts",
           "address_space_limit", "memory_shortage"]

MIN_ADDRESS_SPACE = 1 << 30          # bytes: below this a command cannot load its libraries (600 MB: SIGSEGV)
FULL_SCAN_ADDRESS_SPACE = 3584 << 20  # bytes: `rangekit sim render` worked at 3.5 GB, not at 2.5 GB

_sigint_seen = False       # a SIGINT arrived since prepare()
_sigint_pending = False    # ... and no KeyboardInterrupt has reached the command line's handler yet


def _on_sigint(signum, frame) -> None:
    global _sigint_seen, _sigint_pending
    _sigint_seen = _sigint_pending = True
    raise KeyboardInterrupt


class _InterruptAtNextImport:
    """A meta-path finder that raises the KeyboardInterrupt a library swallowed: Ctrl-C while Open3D's
    extension initialises is caught there, and the command would run on to the end. The next first import
    (there are many on every command's way) raises it again."""

    @staticmethod
    def find_spec(name, path=None, target=None):
        global _sigint_pending
        if _sigint_pending:
            _sigint_pending = False
            raise KeyboardInterrupt
        return None


def prepare() -> None:
    """Escape unencodable characters on stdout and stderr (``PYTHONIOENCODING=ascii``)."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.reconfigure(errors="backslashreplace")
        except (AttributeError, ValueError, OSError):
            pass   # not a text stream we own (a test's capture, a closed stream)


def _quiet_interrupt(hook):
    """An unraisable-exception hook that says nothing of a KeyboardInterrupt a C callback swallowed (a Ctrl-C while
    numba's compiler wrote its cache: llvmlite's callback printed a traceback) and leaves it pending, so the next
    import raises it (:class:`_InterruptAtNextImport`); anything else goes to ``hook``."""
    def quiet(unraisable) -> None:
        global _sigint_pending
        if isinstance(unraisable.exc_value, KeyboardInterrupt):
            _sigint_pending = True
            return
        hook(unraisable)
    return quiet


@contextmanager
def watching_interrupts():
    """While the command runs: note SIGINTs, and raise one a library swallowed at the next first import
    (main thread only; a SIGINT the shell ignores stays ignored). Everything is put back afterwards, so a
    process that calls the command line in-process (the tests) keeps its own handling."""
    global _sigint_seen, _sigint_pending
    _sigint_seen = _sigint_pending = False
    try:
        previous = signal.getsignal(signal.SIGINT)
        if previous is getattr(sys.modules.get("rangekit"), "_interrupted_while_starting", None):
            previous = signal.default_int_handler   # rangekit/__init__'s start-up handler ends here
        ours = previous is signal.default_int_handler
        if ours:
            signal.signal(signal.SIGINT, _on_sigint)
    except ValueError:   # not the main thread: leave signals alone
        ours = False
    if ours:
        sys.meta_path.insert(0, _InterruptAtNextImport)
        hook = sys.unraisablehook
        sys.unraisablehook = _quiet_interrupt(hook)
    try:
        yield
    finally:
        if ours:
            sys.unraisablehook = hook
            # Interrupted, the process is about to exit 130: a SIGINT re-delivered late (Open3D's extension
            # hands one back after its initialisation) or a second Ctrl-C must not kill it by signal then.
            signal.signal(signal.SIGINT, signal.SIG_IGN if _sigint_seen else previous)
            sys.meta_path.remove(_InterruptAtNextImport)
        _sigint_pending = False


def interrupted() -> bool:
    """Whether a SIGINT arrived since :func:`prepare` (an ImportError may be its disguise)."""
    return _sigint_seen


def address_space_limit() -> int | None:
    """The soft RLIMIT_AS in bytes (``ulimit -v`` x 1024), or None when unlimited."""
    import resource

    soft = resource.getrlimit(resource.RLIMIT_AS)[0]
    return None if soft == resource.RLIM_INFINITY else int(soft)


def problems() -> tuple[str, str]:
    """("usage" or "resource", message) for the first problem of the surroundings, or ("", "")."""
    try:
        os.getcwd()
    except OSError:
        return "usage", ("the working folder no longer exists (deleted or moved while the shell was in it); "
                         "cd to an existing folder and run the command again")
    threads = os.environ.get("NUMBA_NUM_THREADS")
    if threads is not None:
        try:
            ok = int(threads) >= 1
        except ValueError:
            ok = False
        if not ok:
            return "usage", (f"NUMBA_NUM_THREADS={threads!r}: expected a whole number of threads >= 1; unset it to "
                             f"use every core")
    limit = address_space_limit()
    if limit is not None and limit < MIN_ADDRESS_SPACE:
        return "resource", (f"the address-space limit (ulimit -v) is {limit >> 20} MB; rangekit needs at least "
                            f"{MIN_ADDRESS_SPACE >> 20} MB to load its libraries and about "
                            f"{FULL_SCAN_ADDRESS_SPACE >> 20} MB for a scan: raise it (ulimit -v unlimited)")
    return "", ""


_SHORTAGE_WORDS = ("failed to map segment", "cannot allocate memory", "insufficient memory", "out of memory",
                   "could not find/load shared object", "failed to allocate")


def memory_shortage(exc: BaseException) -> str:
    """A one-line message when ``exc`` looks like running out of address space under a ``ulimit -v`` below
    what a scan needs, else ""."""
    limit = address_space_limit()
    if limit is None or limit >= FULL_SCAN_ADDRESS_SPACE:
        return ""
    text = str(exc).lower()
    if not (isinstance(exc, MemoryError) or any(w in text for w in _SHORTAGE_WORDS)):
        return ""
    detail = " ".join(str(exc).split())[:160]
    return (f"out of memory under the address-space limit (ulimit -v) of {limit >> 20} MB ({type(exc).__name__}: "
            f"{detail}); a scan needs about {FULL_SCAN_ADDRESS_SPACE >> 20} MB: raise the limit")
