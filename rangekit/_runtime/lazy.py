"""Packages whose names load on first use (PEP 562), so importing one of their modules does not import the
others: ``rangekit.formats`` (``rangekit decode`` needs the capture reader, not scipy) and
``rangekit.surface`` (Poisson's child process needs the fusion, not numba's closing kernels)."""

from __future__ import annotations

import importlib
import sys
from typing import Callable

__all__ = ["lazy_exports"]


def lazy_exports(package: str, module_of: dict[str, str], names: list[str]) -> tuple[Callable, Callable]:
    """The package's ``(__getattr__, __dir__)``: ``module_of`` maps each exported name to its module (relative
    to ``package``); an attribute that is no exported name is imported as a submodule, or is an
    AttributeError. A loaded name is kept in the package's namespace (the next access is plain)."""

    def __getattr__(name: str):
        if name in module_of:
            value = getattr(importlib.import_module(f"{package}.{module_of[name]}"), name)
            setattr(sys.modules[package], name, value)
            return value
        try:
            return importlib.import_module(f"{package}.{name}")
        except ModuleNotFoundError as exc:
            if exc.name != f"{package}.{name}":
                raise
            raise AttributeError(f"module {package!r} has no attribute {name!r}") from None

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[package])) | set(names))

    return __getattr__, __dir__
