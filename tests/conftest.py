"""The suite's shared fixtures: ``rig`` (the default simulated rig), ``small_rig`` (it with a 320x256 camera),
``cli(*args)`` (``rangekit ARGS`` in this process: a :class:`cli_runs.Run` with the exit code, stdout and
stderr; argparse's own exits caught), ``reference_session`` (a small finished simulated session, made once per
run: tests/support/sessions.py) and ``tmp_session`` (a fresh copy of it for one test to change); ``decoded_graycode`` (the
small projector rig's Gray-code capture of the default scene, decoded); scenes and imaging."""

import ctypes
import ctypes.util
import gc
import os
import shutil

import numpy as np
import pytest

from rangekit.geometry import axis_angle_to_R, make_T
from rangekit.sim import ImagingModel, Scene, default_rig
from rangekit.sim.scene.objects import box, plane


@pytest.fixture(scope="session")
def rig():
    return default_rig()


@pytest.fixture(scope="session")
def small_rig():
    from support.small_rigs import small_rig as make

    return make()


@pytest.fixture
def cli(capsys):
    from support.cli_runs import Run
    from rangekit.cli import main

    def run(*args) -> Run:
        capsys.readouterr()
        try:
            code = main([str(a) for a in args])
        except SystemExit as stop:  # argparse: --help, or a usage error
            code = stop.code if isinstance(stop.code, int) else 1
        captured = capsys.readouterr()
        return Run(code, captured.out, captured.err)

    return run


@pytest.fixture(scope="session")
def reference_session(tmp_path_factory):
    """A finished simulated session as ``rangekit scan`` makes it (tests/support/sessions.py: 4 views of the lumpy object,
    seed 1, Gray code, the small rig). Read it; copy it (``tmp_session``) to change it."""
    from support.sessions import make_reference

    return make_reference(tmp_path_factory.mktemp("reference") / "s")


@pytest.fixture
def tmp_session(reference_session, tmp_path):
    """A copy of ``reference_session`` of this test's own."""
    return shutil.copytree(reference_session, tmp_path / "session")


@pytest.fixture(scope="session")
def tilted_plane_scene():
    """A large plane through the table centre, tilted 20 deg about x and 15 deg about z (off the table)."""
    R = axis_angle_to_R([0, 0, 1], np.radians(15)) @ axis_angle_to_R([1, 0, 0], np.radians(70))
    obj = plane(1.0, 1.0).with_pose(make_T(R, [0.0, 0.02, 0.06]))
    return Scene((obj,))


@pytest.fixture(scope="session")
def box_on_plane_scene():
    ground = plane(1.0, 1.0, albedo=0.6)
    cube = box((0.06, 0.05, 0.08), albedo=0.8).placed_on_table(xy=(0.01, 0.0))
    return Scene((ground, cube))


@pytest.fixture(scope="session")
def noiseless():
    return ImagingModel().noiseless()


@pytest.fixture(scope="session")
def decoded_graycode():
    """``(rig, DecodeResult)``: the small projector rig (tests/support/small_rigs.py) and its Gray-code capture (columns and
    rows) of the default scene, seed 1, decoded."""
    from rangekit.coded.decode import decode
    from rangekit.coded.patterns import make_pattern_spec
    from rangekit.sim import SimRig, default_scene
    from support.small_rigs import small_projector_rig

    rig = small_projector_rig()
    spec = make_pattern_spec("graycode", (rig.projector.width, rig.projector.height))
    return rig, decode(SimRig(default_scene(), rig, seed=1).capture_sequence(list(spec.frames())), spec)


_LIBC = ctypes.CDLL(ctypes.util.find_library("c")) if ctypes.util.find_library("c") else None
_PAGE = os.sysconf("SC_PAGE_SIZE")
_RSS_AFTER_LAST_FREE = [0]


def _rss() -> int:
    """Resident bytes of this process."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * _PAGE


#: The worker's glibc mmap threshold between tests (its trim threshold twice that).
_WORKER_MMAP_BYTES = 1 << 20
#: A worker holding more than this after a module drops the library's caches (:func:`_collect_after_module`).
_CACHES_KEPT_BELOW = 900 << 20


def _free_memory() -> None:
    """Collect the cycles and hand the free heap back; and the worker's glibc limits back to 1 MB: an in-process
    scan's :func:`rangekit._runtime.memory.reuse_freed_memory` leaves them at 32 MB (as a long scan wants), and the
    worker's heap then holds every array under 32 MB of every later test, fragmented (docs/benchmarks.md, "Issue 51, eighth stop")."""
    from rangekit._runtime import memory

    gc.collect()
    if _LIBC is not None and hasattr(_LIBC, "malloc_trim"):
        if memory._MALLOPT is not None and "MALLOC_MMAP_THRESHOLD_" not in os.environ:
            memory._MALLOPT(memory._M_MMAP_THRESHOLD, _WORKER_MMAP_BYTES)
            memory._MALLOPT(memory._M_TRIM_THRESHOLD, 2 * _WORKER_MMAP_BYTES)
        _LIBC.malloc_trim(0)
    _RSS_AFTER_LAST_FREE[0] = _rss()


@pytest.fixture(autouse=True)
def _return_freed_memory():
    """After a test that grew the process by more than 256 MB, free what reference cycles hold (a dropped
    simulator holds its full-size maps in a cycle, and the cyclic collector counts objects, not bytes)
    and hand the freed heap back to the system (glibc keeps it otherwise, and the suite's resident
    memory would grow test after test). Small tests skip the collection, which costs time."""
    yield
    if _rss() - _RSS_AFTER_LAST_FREE[0] > 256 << 20:
        _free_memory()


@pytest.fixture(autouse=True)
def _logger_as_imported():
    """A command run with -q or -v sets the rangekit logger's level; the next test starts from the default."""
    yield
    from rangekit.progress import LOGGER

    LOGGER.setLevel(0)


@pytest.fixture(scope="module", autouse=True)
def _collect_after_module():
    """After each module the freed heap handed back, and where the worker then holds more than
    :data:`_CACHES_KEPT_BELOW`, the library's caches of large arrays emptied too (a module's rigs and boards are
    seldom the next one's; emptied after every module, the arrays made again would cost CPU in every module)."""
    yield
    _free_memory()
    if _rss() > _CACHES_KEPT_BELOW:
        from rangekit._runtime.memory import forget_caches

        forget_caches()
        _RSS_AFTER_LAST_FREE[0] = _rss()


#: The modules whose tests take the most memory: those of tests/ui (each starts a ``rangekit ui``, 0.7-1.3 GB
#: once its live frames and jobs ran) and those whose tests grow their worker by 0.8-1.1 GB (full-size
#: simulated captures and their truth; ``benchmarks/harness/suite_memory.py`` names them).
MEMORY_HEAVY = ("tests/ui/", "tests/sim/test_sim.py", "tests/coded/test_coded_light.py",
                "tests/calib/test_calibration.py", "tests/app/scan/test_scan_call.py", "tests/rig/test_response.py",
                "tests/coded/test_hybrid_min_bit.py")


def pytest_collection_modifyitems(config, items):
    """The memory-heavy modules (:data:`MEMORY_HEAVY`) share one pytest-xdist worker, one after another, where the
    run distributes by group (``-n 2 --dist loadgroup``, as ``make test`` runs): two of them at once, one on
    each worker, took ``make test`` over the 4 GB of the machine it is kept under."""
    for item in items:
        if item.nodeid.startswith(MEMORY_HEAVY):
            item.add_marker(pytest.mark.xdist_group("memory-heavy"))


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item, call):
    """A test (or its fixture) that needs the shared real data and finds it missing (MissingDataError, naming the
    file and the folders looked in) is skipped with that reason, not failed: a bare clone passes ``make test``
    (``make test-bare`` hides the data and runs the suite)."""
    from rangekit.errors import MissingDataError

    outcome = yield
    report = outcome.get_result()
    if call.excinfo is not None and call.excinfo.errisinstance(MissingDataError):
        report.outcome = "skipped"
        report.longrepr = (str(item.path), item.location[1] or 0, f"Skipped: {call.excinfo.value}")
