"""Packages whose names load on first use (PEP 562), so importing one of their modules does not import the
others: ``rangekit.formats`` (``rangekit decode`` needs the capture reader, not scipy) and
``rangekit.surface`` (Poisson's child process needs the fusion, not numba's closing kernels)."""

from __future__ import annotations

import ast
import importlib
import sys
from pathlib import Path
from typing import Callable

__all__ = ["attach_stub", "lazy_exports"]


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


def attach_stub(package: str, init_file: str) -> tuple[Callable, Callable, list[str]]:
    """The package's ``(__getattr__, __dir__, __all__)`` from the ``__init__.pyi`` beside its ``__init__.py``
    (scikit-image's way): each ``from .module import name as name`` line of the stub is one name, loaded from
    that module on first use (:func:`lazy_exports`); type checkers and readers see the same lines. A name that is
    also its module's name (``rangekit.coded.decode``, the function of the module ``decode``) is imported at
    once: Python binds a submodule, when it loads, over the package's attribute of that name.

    Raises ValueError naming the stub for any other statement than a docstring and ``from .x import y``."""
    stub = Path(init_file).with_suffix(".pyi")
    module_of: dict[str, str] = {}
    for k, node in enumerate(ast.parse(stub.read_text(encoding="utf-8")).body):
        if isinstance(node, ast.ImportFrom) and node.level == 1 and node.module:
            module_of.update({a.asname or a.name: node.module for a in node.names})
        elif not (k == 0 and isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant)):
            raise ValueError(f"{stub}, line {node.lineno}: expected only 'from .module import name as name' lines")
    names = list(module_of)
    get, listed = lazy_exports(package, module_of, names)
    for name, module in module_of.items():
        if module == name:      # a direct submodule of that name
            setattr(sys.modules[package], name, get(name))
    return get, listed, names
