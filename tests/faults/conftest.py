"""The ``cli`` fixture of the fault-injection tests (issue 16).

``cli(*args)`` runs ``rangekit ARGS`` in this process (fast: no interpreter start, no open3d import) and
returns a :class:`_faults.Run` (exit code, stdout, stderr); argparse's own exits are caught.
"""

from __future__ import annotations

import pytest

from _faults import Run


@pytest.fixture
def cli(capsys):
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
