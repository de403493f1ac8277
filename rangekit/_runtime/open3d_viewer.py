"""Open3D without its plotly viewer loaded up front, in rangekit's own processes.

``import open3d`` imports ``open3d.visualization.draw_plotly``, which imports dash, plotly, IPython,
werkzeug and pydantic, in every process that ray-casts or runs Poisson and never draws with plotly.
:func:`defer_plotly_viewer`, called where rangekit owns the process (the command line, Poisson's child
process) before Open3D is imported, puts a stand-in for that module in ``sys.modules``: its functions
import the real viewer when first called, then are replaced by the real ones, so
``open3d.visualization.draw_plotly(...)`` still works there, a first call later.

What it saves, CPU seconds of ``import open3d`` and the process's resident size after it (two runs each,
2-core machine of 2026-11-24): 0.88-0.92 s and 220 MB without, 0.51-0.53 s and 178 MB with::

    python -c "import time, psutil; t = time.process_time(); import open3d; \
print(time.process_time() - t, psutil.Process().memory_info().rss)"
    python -c "import time, psutil; from rangekit._runtime.open3d_viewer import defer_plotly_viewer; \
defer_plotly_viewer(); t = time.process_time(); import open3d; \
print(time.process_time() - t, psutil.Process().memory_info().rss)"
"""

from __future__ import annotations

import importlib
import sys
import types

__all__ = ["defer_plotly_viewer"]

VIEWER = "open3d.visualization.draw_plotly"


def defer_plotly_viewer() -> None:
    """Stand in for Open3D's plotly viewer module until one of its functions is called (nothing when Open3D
    or the viewer is already imported)."""
    if "open3d" in sys.modules or VIEWER in sys.modules:
        return
    stand_in = types.ModuleType(VIEWER, "Open3D's plotly viewer, imported on the first call (rangekit._runtime.open3d_viewer)")

    def deferred(name: str):
        if name.startswith("__"):
            raise AttributeError(name)

        def call(*args, **kwargs):
            return getattr(_real_viewer(stand_in), name)(*args, **kwargs)

        call.__name__ = call.__qualname__ = name
        call.__deferred__ = True
        return call

    stand_in.__getattr__ = deferred
    sys.modules[VIEWER] = stand_in


def _real_viewer(stand_in: types.ModuleType) -> types.ModuleType:
    """Import the real viewer in place of ``stand_in`` and rebind the names ``open3d.visualization`` took from
    it (importing the submodule sets the package's ``draw_plotly`` to the module itself)."""
    if sys.modules.get(VIEWER) is stand_in:
        del sys.modules[VIEWER]
    real = importlib.import_module(VIEWER)
    package = sys.modules[VIEWER.rpartition(".")[0]]
    for name, value in list(vars(package).items()):
        if name == "draw_plotly" or getattr(value, "__deferred__", False):
            setattr(package, name, getattr(real, name))
    return real
