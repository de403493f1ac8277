"""Issue 49: the stages stay pure. No stage module imports ``rangekit._runtime``, ``threading``,
``concurrent.futures`` or ``multiprocessing`` (an ``ast`` walk of the module, the imports inside functions
included): the job runner (rangekit/app/runner.py, rangekit/_runtime/executor.py) owns where work runs, its
threads, children and memory. A synthetic module shows the walk fails where it should."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]

#: The stage modules: each takes a typed input and returns a typed output.
STAGES = ("rangekit/app/process/decode.py", "rangekit/app/process/register.py", "rangekit/app/process/fuse.py",
          "rangekit/app/process/evaluate.py", "rangekit/app/process/fused_outputs.py", "rangekit/app/process/laser.py",
          "rangekit/app/report/page.py",
          # the scan's per-view steps: the runner's STREAMING worker runs them (rangekit.app.runner.StreamingWorker)
          "rangekit/app/scan/streaming.py")
#: What a stage may not import (a module or anything under it).
FORBIDDEN = ("rangekit._runtime", "threading", "concurrent.futures", "multiprocessing")


def forbidden_imports(source: str, module: str = "") -> list[str]:
    """Each forbidden import of ``source`` (any depth: inside functions and classes too), as ``line: name``;
    ``module`` the dotted name of the module, for its relative imports."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = module.split(".")[: -node.level]
                base = ".".join(parts + ([base] if base else []))
            names = [base] + [f"{base}.{a.name}" for a in node.names]
        else:
            continue
        for name in names:
            if any(name == f or name.startswith(f + ".") for f in FORBIDDEN):
                found.append(f"{node.lineno}: {name}")
                break
    return found


@pytest.mark.parametrize("path", STAGES)
def test_no_stage_module_imports_threads_processes_or_the_runtime(path):
    module = path[:-3].replace("/", ".")
    assert forbidden_imports((ROOT / path).read_text(), module) == [], path


SYNTHETIC = '''
import numpy as np
from rangekit.surface.cloud import PointCloud


def stage(x):
    from concurrent.futures import ThreadPoolExecutor   # inside a function
    return x


class Hidden:
    def run(self):
        import threading
        from rangekit._runtime import memory
        from ..._runtime.child import call_beside      # relative
        import multiprocessing.pool
'''


def test_the_walk_finds_each_forbidden_import_however_written():
    found = forbidden_imports(SYNTHETIC, "rangekit.app.process.synthetic")
    assert [f.split(": ")[1] for f in found] == ["concurrent.futures", "threading", "rangekit._runtime",
                                                  "rangekit._runtime.child", "multiprocessing.pool"]
    assert forbidden_imports("import numpy\nfrom rangekit.app.events import Stage\n") == []
