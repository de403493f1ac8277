"""Open3D's plotly viewer deferred in rangekit's processes (rangekit._runtime.open3d_viewer): not imported with
Open3D, and still there, the real thing, when called."""

import os
import subprocess
import sys

SCRIPT = """
import sys
from rangekit._runtime.open3d_viewer import defer_plotly_viewer
defer_plotly_viewer()
import numpy as np
import open3d as o3d
print("plotly imported with open3d:", "plotly" in sys.modules)
cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.random.default_rng(0).random((20, 3))))
figure = o3d.visualization.get_plotly_fig([cloud])
print("figure:", type(figure).__module__.split(".")[0], len(figure.data))
viewer = sys.modules["open3d.visualization.draw_plotly"]
print("rebound:", o3d.visualization.get_plotly_fig is viewer.get_plotly_fig,
      o3d.visualization.draw_plotly is viewer.draw_plotly)
"""


def run(script: str) -> list[str]:
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300,
                         env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)})
    assert out.returncode == 0, out.stderr
    return out.stdout.splitlines()


def test_open3d_loads_without_its_viewer_and_the_viewer_works_when_called():
    assert run(SCRIPT) == ["plotly imported with open3d: False", "figure: plotly 1", "rebound: True True"]


def test_nothing_is_deferred_once_open3d_is_imported():
    lines = run("import sys, open3d\nfrom rangekit._runtime.open3d_viewer import defer_plotly_viewer\n"
                "defer_plotly_viewer()\nprint(type(sys.modules['open3d.visualization.draw_plotly'].draw_plotly))")
    assert lines == ["<class 'function'>"]


def test_the_command_line_defers_the_viewer():
    """rangekit's command line defers it before any command runs (those that ray-cast import Open3D)."""
    lines = run("import sys\nfrom rangekit.cli.run import main\ntry:\n    main(['--version'])\n"
                "except SystemExit:\n    pass\nimport open3d\n"
                "print('plotly imported with open3d:', 'plotly' in sys.modules)")
    assert lines[-1] == "plotly imported with open3d: False"
