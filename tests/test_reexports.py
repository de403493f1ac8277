"""One re-export mechanism (issue 49): a package's names are the lines of its ``__init__.pyi``, loaded on first use
by :func:`rangekit._runtime.lazy.attach_stub`; no package ``__init__.py`` imports its own submodules eagerly."""

import ast
import importlib
from pathlib import Path

import pytest

from rangekit._runtime.lazy import attach_stub

ROOT = Path(__file__).resolve().parents[1]
PACKAGE_OF = {"rangekit": "rangekit", "sim": "rangekit.sim", "calib": "rangekit.calib", "drivers": "rangekit.drivers"}
#: __init__ files that build a fact from their submodules (not a re-export): the capture layouts' LAYOUTS table,
#: the drivers' registry.
BUILDS_FROM_SUBMODULES = {"rangekit/formats/layouts/__init__.py", "drivers/__init__.py"}
STUBS = sorted(ROOT.glob("rangekit/**/__init__.pyi")) + sorted(ROOT.glob("sim/**/__init__.pyi"))


def _package(init: Path) -> str:
    parts = init.parent.relative_to(ROOT).parts
    return ".".join([PACKAGE_OF[parts[0]], *parts[1:]])


def test_stubs_exist_for_the_re_exporting_packages():
    assert {str(s.relative_to(ROOT)) for s in STUBS} >= {"rangekit/__init__.pyi", "rangekit/coded/__init__.pyi",
                                                         "rangekit/formats/__init__.pyi", "sim/__init__.pyi"}


@pytest.mark.parametrize("stub", STUBS, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_stub_name_is_exported_and_loads(stub):
    package = importlib.import_module(_package(stub))
    names = [a.asname or a.name for node in ast.parse(stub.read_text()).body if isinstance(node, ast.ImportFrom)
             for a in node.names]
    assert names and set(names) <= set(package.__all__)
    for name in names:
        assert getattr(package, name) is not None
        assert not hasattr(getattr(package, name), "__path__") or name in ("sim",)   # the name, not a submodule


def test_no_package_init_imports_its_submodules_eagerly():
    found = []
    for init in [*ROOT.glob("rangekit/**/__init__.py"), *ROOT.glob("sim/**/__init__.py"),
                 *ROOT.glob("calib/**/__init__.py"), *ROOT.glob("drivers/**/__init__.py")]:
        rel = str(init.relative_to(ROOT))
        if rel in BUILDS_FROM_SUBMODULES or ".venv" in rel:
            continue
        package = _package(init)
        for node in ast.parse(init.read_text()).body:
            if isinstance(node, ast.ImportFrom) and node.module != "rangekit._runtime.lazy" and (
                    node.level > 0 or (node.module or "").startswith(package + ".")):
                found.append(f"{rel}:{node.lineno}")
    assert not found, f"re-export through __init__.pyi and attach_stub, found eager imports at {found}"


def test_a_function_named_as_its_module_is_the_function():
    import rangekit.coded
    import rangekit.coded.decode   # noqa: F401  (the submodule loaded: Python binds it on the package)
    from rangekit.coded import decode, triangulate

    assert callable(decode) and callable(triangulate) and not hasattr(decode, "__file__")


def test_a_stub_with_anything_else_is_refused(tmp_path):
    (tmp_path / "__init__.pyi").write_text('"""doc"""\nfrom .a import b as b\nimport os\n')
    with pytest.raises(ValueError, match=r"__init__.pyi, line 3: expected only 'from .module import name"):
        attach_stub("rangekit", str(tmp_path / "__init__.py"))
