"""The ``rangekit`` command line (entry point ``rangekit.cli:main``); see :mod:`rangekit.cli.main`."""

from rangekit.cli.main import build_parser, main

__all__ = ["build_parser", "main"]
