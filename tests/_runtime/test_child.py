"""A call in a child process (rangekit._runtime.child): the same answer as in-process, errors carried back, a dead
child reported, an interrupted parent leaves no child behind. Real spawned processes, no mocks."""

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

from rangekit._runtime.child import call_beside, child_call, spawn_child
from rangekit.errors import MeshError, RangekitError
from rangekit.surface.cloud import PointCloud
from rangekit.surface.fusion import poisson_meshes


def sphere_cloud(n=20_000, seed=0):
    rng = np.random.default_rng(seed)
    p = rng.normal(size=(n, 3))
    p /= np.linalg.norm(p, axis=1, keepdims=True)
    return PointCloud(0.05 * p, np.full((n, 3), 0.5), p)


def killed_by_a_signal():
    os.kill(os.getpid(), signal.SIGKILL)


def sleeping(seconds):
    time.sleep(seconds)
    return seconds


def mesh_arrays(fused):
    return [np.asarray(a) for m in (fused.observed, fused.watertight) for a in (m.vertices, m.triangles)]


def test_poisson_in_a_child_gives_the_same_meshes_as_on_a_thread_bit_for_bit():
    cloud = sphere_cloud()
    answers = []
    for in_child in (True, False):
        with call_beside(poisson_meshes, cloud, depth=6, n_threads=1, in_child=in_child) as call:
            answers.append(mesh_arrays(call.result()))
    assert len(answers[0][0]) > 1000
    for a, b in zip(*answers):
        assert a.dtype == b.dtype and np.array_equal(a, b)


def test_a_rangekit_error_in_the_child_is_raised_as_it_was():
    with child_call(poisson_meshes, sphere_cloud(5)) as call:
        with pytest.raises(MeshError, match="5 points with a normal"):
            call.result()


def test_another_error_carries_the_childs_traceback():
    with child_call(np.zeros, (-1,)) as call:
        with pytest.raises(RuntimeError, match=r"(?s)ValueError: negative dimensions.*in the child process"):
            call.result()


def test_a_child_that_dies_without_an_answer_is_an_error_naming_the_call_and_the_signal():
    with child_call(killed_by_a_signal) as call:
        with pytest.raises(RangekitError, match=r"test_child\.killed_by_a_signal in a child process ended without "
                                                r"an answer \(exit code -9"):
            call.result()


def test_an_error_in_the_parent_ends_the_child_at_once():
    with pytest.raises(KeyboardInterrupt):
        with child_call(sleeping, 60) as call:
            raise KeyboardInterrupt
    assert call._proc.returncode == -signal.SIGTERM   # ended, not waited for


def kind_of_call_in_this_process():
    with call_beside(os.getpid, in_child=True) as call:
        return type(call).__name__, call.result() == os.getpid()


def test_a_daemonic_process_such_as_a_dask_worker_runs_the_call_on_a_thread():
    import multiprocessing

    with multiprocessing.get_context("spawn").Pool(1) as pool:    # a pool's workers are daemonic
        assert pool.apply(kind_of_call_in_this_process) == ("ThreadCall", True)
    assert kind_of_call_in_this_process() == ("ChildCall", False)   # here: a child, another pid


def test_a_script_without_a_main_guard_is_not_run_again_in_the_child(tmp_path):
    """multiprocessing's spawn would import the caller's script again in the child; a plain child does not."""
    script = tmp_path / "unguarded.py"
    marker = tmp_path / "runs.txt"
    script.write_text(f"""
import os
from rangekit._runtime.child import child_call
with open({str(marker)!r}, "a") as f:
    f.write("run\\n")
with child_call(os.getpid) as call:
    print(call.result() != os.getpid())
""")
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=120,
                         env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert out.returncode == 0 and out.stdout.strip() == "True", out.stderr
    assert marker.read_text().splitlines() == ["run"]


def test_prints_in_the_child_go_to_stderr_and_leave_the_answer_intact():
    with child_call(print, "a line from the child") as call:
        assert call.result() is None


def imported(name):
    return name in sys.modules


def test_a_child_spawned_ahead_imports_its_modules_before_the_call_arrives():
    with spawn_child(("colorsys",)) as child:
        assert call_beside(imported, "colorsys", in_child=True, child=child).result() is True
    with child_call(imported, "colorsys") as call:     # a plain child has not imported it
        assert call.result() is False


def test_a_spawned_child_not_used_is_ended_with_its_block():
    with spawn_child(("colorsys",)) as child:
        pass
    assert child._proc.returncode is not None


def loaded(*names):
    return [name for name in names if name in sys.modules]


def test_poissons_child_loads_open3d_and_the_fusion_without_numba_scipy_or_plotly():
    """Processing's Poisson child holds its octree beside the main process: what it imports counts at the
    peak (numba and scipy came with rangekit.surface's package import: 89 MB; plotly with Open3D: 42 MB)."""
    from rangekit.app.process.fuse import CHILD_IMPORTS

    with spawn_child(CHILD_IMPORTS) as child:
        got = call_beside(loaded, "open3d", "rangekit.surface.fusion", "numba", "scipy", "plotly", "dash",
                          in_child=True, child=child).result()
    assert got == ["open3d", "rangekit.surface.fusion"]


def summed_messages(start):
    from rangekit._runtime.child import messages

    return start + sum(int(x.sum()) for x in messages())


def test_a_call_with_more_reads_every_message_sent_until_its_result():
    import numpy as np

    parts = [np.arange(n * 100_000, dtype=np.int64) for n in range(1, 5)]    # 0.8-3.2 MB each: more than a pipe holds
    with spawn_child() as child:
        child.start(summed_messages, (7,), more=True)
        for p in parts:
            child.send(p)
        assert child.result() == 7 + sum(int(p.sum()) for p in parts)
    with child_call(summed_messages, 3) as call:           # no more: the call reads none
        assert call.result() == 3


def test_a_call_with_more_ended_before_its_messages_leaves_no_process():
    with spawn_child() as child:
        child.start(summed_messages, (0,), more=True)
        child.send(np_zeros())
    assert child._proc.returncode is not None and not child._writer.is_alive()


def np_zeros():
    import numpy as np

    return np.zeros(10)
