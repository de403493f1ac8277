"""The package's shape: no import cycle, imports only go down the layers, no module over 600 lines (a warning
over 400: split a file by idea, not by length), no folder of more than 15 modules, every package installed.

Every ``import`` and ``from ... import`` statement of every module is read with ``ast``, including
imports inside functions and under ``if TYPE_CHECKING:`` (a cycle hidden in a function is still a
cycle). Module names are the installed ones: ``sim/scene/raycast.py`` is ``rangekit.sim.scene.raycast``.
"""

from __future__ import annotations

import ast
import re
import warnings
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PYPROJECT = ROOT / "pyproject.toml"
#: Source folders and the package each one installs as (pyproject's package-dir).
FOLDERS = {"rangekit": "rangekit", "sim": "rangekit.sim", "drivers": "rangekit.drivers", "calib": "rangekit.calib"}

#: Layer of each part, lowest first; a module may import its own layer or a lower one, never a higher.
#: Core modules (errors, geometry, camera, io, ...) are the top-level modules of rangekit/.
LAYERS = {
    "core": 0,
    "coded": 1, "stereo": 1, "photometric": 1, "tof": 1, "surface": 1, "registration": 1, "laser": 1, "metrology": 1,
    "rendering": 1,
    "formats": 2,
    "sim": 3, "drivers": 3, "calib": 3,
    "app": 4,
    "ui": 5,
    "cli": 6,
}
#: Pairs of parts on one layer that must not import each other either way.
APART = [("sim", "drivers"), ("sim", "calib"), ("drivers", "calib")]
#: A module over LONG_LINES lines is reported as a warning; one over MAX_LINES fails.
LONG_LINES = 400
MAX_LINES = 600
#: The most modules (``.py`` files, ``__init__.py`` included) one folder may hold: more wants a room of its own.
MAX_MODULES_PER_FOLDER = 15


def _module_name(path: Path) -> str:
    folder = path.relative_to(ROOT).parts[0]
    rel = path.relative_to(ROOT / folder).with_suffix("")
    parts = [p for p in rel.parts if p != "__init__"]
    return ".".join([FOLDERS[folder], *parts])


def _sources() -> dict[str, Path]:
    # (A development checkout may link rangekit/sim -> ../sim; each source is read once, from its folder.)
    return {_module_name(p): p for folder in FOLDERS for p in sorted((ROOT / folder).rglob("*.py"))
            if "__pycache__" not in p.parts and not (folder == "rangekit" and p.parts[len(ROOT.parts) + 1] in FOLDERS)}


def _part(module: str) -> str:
    """The part of the package a module belongs to: ``rangekit.coded.decode`` -> ``coded``."""
    parts = module.split(".")
    if len(parts) == 1:
        return "core"
    if parts[1] == "__main__":
        return "cli"  # python -m rangekit
    if parts[1] in LAYERS:
        return parts[1]
    return "core"  # a top-level module of rangekit/


def _imports(path: Path, module: str, known: set[str]) -> set[str]:
    """The rangekit modules ``path`` imports, anywhere in the file."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = module if path.name == "__init__.py" else module.rsplit(".", 1)[0]
    found: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")
                base = base[:len(base) - node.level + 1]
                src = ".".join(base + ([node.module] if node.module else []))
            else:
                src = node.module or ""
            # `from rangekit.coded import decode` imports the module rangekit.coded.decode.
            names = [f"{src}.{a.name}" if f"{src}.{a.name}" in known else src for a in node.names]
        else:
            continue
        for name in names:
            if name == "rangekit" or not name.startswith("rangekit."):
                continue
            while name not in known and "." in name:
                name = name.rsplit(".", 1)[0]
            if name in known and name != module:
                found.add(name)
    return found


@pytest.fixture(scope="module")
def graph() -> dict[str, set[str]]:
    src = _sources()
    known = set(src)
    return {m: _imports(p, m, known) for m, p in src.items()}


def test_the_tree_is_read(graph):
    # The walk must see the package (so the other tests cannot pass on an empty graph).
    assert len(graph) > 60
    for m in ("rangekit.camera", "rangekit.sim.scene.raycast", "rangekit.drivers.turntable", "rangekit.calib.camera",
              "rangekit.registration.icp", "rangekit.cli"):
        assert m in graph, m
    assert "rangekit.geometry" in graph["rangekit.camera"]


def _find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One import cycle as a list of modules, or None (iterative depth-first search)."""
    state: dict[str, int] = {}   # 1 on the stack, 2 done
    for start in sorted(graph):
        if state.get(start):
            continue
        stack = [(start, iter(sorted(graph[start])))]
        path = [start]
        state[start] = 1
        while stack:
            node, children = stack[-1]
            child = next(children, None)
            if child is None:
                state[node] = 2
                stack.pop()
                path.pop()
            elif state.get(child) == 1:
                return path[path.index(child):] + [child]
            elif not state.get(child):
                state[child] = 1
                path.append(child)
                stack.append((child, iter(sorted(graph[child]))))
    return None


def test_no_import_cycle(graph):
    cycle = _find_cycle(graph)
    assert cycle is None, "import cycle: " + " -> ".join(cycle)


def test_the_cycle_finder_finds_cycles():
    assert _find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _find_cycle({"a": {"b"}, "b": set(), "c": {"a", "b"}}) is None


def test_imports_go_down_the_layers(graph):
    upward = []
    for m, deps in graph.items():
        for d in deps:
            pm, pd = _part(m), _part(d)
            if LAYERS[pd] > LAYERS[pm] or (pm, pd) in APART or (pd, pm) in APART:
                upward.append(f"{m} ({pm}) imports {d} ({pd})")
    assert not upward, "imports against the layers:\n" + "\n".join(sorted(upward))


def test_layer_check_catches_an_upward_import():
    assert LAYERS[_part("rangekit.app.process.process")] > LAYERS[_part("rangekit.surface.mesh")]
    assert _part("rangekit.camera") == "core" and _part("rangekit.sim.devices.sim_rig") == "sim"


def test_no_module_over_600_lines():
    lengths = {p: len(p.read_text().splitlines()) for p in _sources().values()}
    long = [f"{p.relative_to(ROOT)}: {n} lines" for p, n in lengths.items() if LONG_LINES < n <= MAX_LINES]
    if long:
        warnings.warn("modules over 400 lines (split by idea if they hold more than one):\n" + "\n".join(long))
    too_long = [f"{p.relative_to(ROOT)}: {n} lines" for p, n in lengths.items() if n > MAX_LINES]
    assert not too_long, "modules over 600 lines:\n" + "\n".join(too_long)


def _folders() -> dict[Path, int]:
    """Every source folder (rangekit/, sim/, drivers/, calib/, benchmarks/, tools/ and below) with how many modules
    it holds."""
    counts: dict[Path, int] = {}
    for top in (*FOLDERS, "benchmarks", "tools"):
        for p in (ROOT / top).rglob("*.py"):
            if "__pycache__" in p.parts or (top == "rangekit" and p.parts[len(ROOT.parts) + 1] in FOLDERS):
                continue
            counts[p.parent] = counts.get(p.parent, 0) + 1
    return counts


def test_no_folder_over_15_modules():
    counts = _folders()
    assert ROOT / "rangekit" / "app" / "report" in counts
    crowded = [f"{d.relative_to(ROOT)}: {n} modules" for d, n in sorted(counts.items()) if n > MAX_MODULES_PER_FOLDER]
    assert not crowded, "folders over 15 modules (give a family its own folder):\n" + "\n".join(crowded)


def test_every_package_is_installed():
    # pyproject lists the packages one by one (rangekit.sim lives in sim/): a new folder missing from the list
    # works in this checkout but is left out of a wheel.
    listed = set(re.findall(r'"(rangekit[\w.]*)"', PYPROJECT.read_text().split("packages = [", 1)[1].split("]", 1)[0]))
    found = {_module_name(p) for p in _sources().values() if p.name == "__init__.py"}
    assert found - listed == set(), "packages missing from pyproject.toml: " + ", ".join(sorted(found - listed))
    assert listed - found == set(), "pyproject.toml lists packages that do not exist: " + ", ".join(sorted(listed - found))


#: Modules of one folder whose names share a first or last word (``scan_job``, ``check_job``, ...): at this many
#: they are a family, and a family gets a room of its own (``ui/jobs/``), a folder named for the idea.
FAMILY_SIZE = 3


def _families(names: list[str]) -> dict[str, list[str]]:
    """Families among module names (stems): ``{"*_job": [...], "depthai_*": [...]}`` with at least FAMILY_SIZE."""
    found: dict[str, list[str]] = {}
    for name in names:
        words = name.strip("_").split("_")
        if len(words) > 1:
            found.setdefault(f"{words[0]}_*", []).append(name)
            found.setdefault(f"*_{words[-1]}", []).append(name)
    return {k: sorted(v) for k, v in found.items() if len(v) >= FAMILY_SIZE}


def test_a_family_of_modules_has_its_own_folder():
    crowded = []
    for folder in (f for f in _folders() if f.relative_to(ROOT).parts[0] in FOLDERS):   # benchmarks: bench_*
        names = [p.stem for p in folder.glob("*.py") if p.stem != "__init__"]
        crowded += [f"{folder.relative_to(ROOT)}: {k} {v}" for k, v in _families(names).items()]
    assert not crowded, "modules named for one idea (give them a folder of that name):\n" + "\n".join(crowded)


def test_the_family_rule_finds_a_family():
    assert _families(["scan_job", "check_job", "register_job", "paths"]) == {
        "*_job": ["check_job", "register_job", "scan_job"]}
    assert _families(["bundle_schur", "bundle_reduced", "camera"]) == {}


def _app_room(module: str) -> str | None:
    parts = module.split(".")
    return ".".join(parts[:3]) if len(parts) > 3 and parts[1] == "app" else None


def test_no_two_app_rooms_import_each_other(graph):
    edges = {(_app_room(m), _app_room(d)) for m, deps in graph.items() for d in deps
             if _app_room(m) and _app_room(d) and _app_room(m) != _app_room(d)}
    both = sorted(f"{a} <-> {b}" for a, b in edges if (b, a) in edges and a < b)
    assert not both, "app folders importing each other both ways (one of them is the lower room):\n" + "\n".join(both)
