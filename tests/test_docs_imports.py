"""The docs name the code as it is: every ``from rangekit... import ...`` line and every dotted
``rangekit.x.y`` name quoted in README.md and docs/*.md imports or resolves."""

from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = sorted([ROOT / "README.md", *(ROOT / "docs").glob("*.md")])
FROM_IMPORT = re.compile(r"from (rangekit[\w.]*) import (\([\w, \n]+\)|[\w ,]+)")
# A dotted name; a schema id such as rangekit.session/1 is not a name (followed by '/'), nor a
# pattern such as rangekit.io.atomic_write_* (followed by '*').
DOTTED = re.compile(r"\b(rangekit(?:\.\w+)+)(?![\w/*])")


def _resolve(dotted: str):
    """The module or attribute ``dotted`` names; raises ImportError or AttributeError."""
    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:k]))
        except ModuleNotFoundError:
            continue
        for name in parts[k:]:
            obj = getattr(obj, name)
        return obj
    raise ImportError(dotted)


def _quoted(pattern: re.Pattern) -> list[tuple[str, re.Match]]:
    return [(f"{p.relative_to(ROOT)}", m) for p in DOCS for m in pattern.finditer(p.read_text())]


def test_docs_are_found():
    assert len(DOCS) > 10
    assert len(_quoted(FROM_IMPORT)) >= 5 and len(_quoted(DOTTED)) >= 50


def test_every_quoted_import_line_imports():
    bad = []
    for where, m in _quoted(FROM_IMPORT):
        # `a as b, c` -> a, c; after the last name on a line the prose goes on.
        names = [n.split()[0] for n in m.group(2).strip("()").replace("\n", " ").split(",") if n.strip()]
        for name in names:
            try:
                _resolve(f"{m.group(1)}.{name}")
            except (ImportError, AttributeError) as exc:
                bad.append(f"{where}: from {m.group(1)} import {name}: {exc!r}")
    assert not bad, "\n".join(bad)


def test_every_dotted_name_resolves():
    bad = []
    for where, m in _quoted(DOTTED):
        name = m.group(1).rstrip(".")
        if name.endswith((".py", ".json", ".ply", ".html", ".md")):
            continue
        try:
            _resolve(name)
        except (ImportError, AttributeError) as exc:
            bad.append(f"{where}: {name}: {exc!r}")
    assert not bad, "\n".join(sorted(set(bad)))


@pytest.mark.parametrize("dotted", ["rangekit.nothing_here", "rangekit.camera.NoSuchCamera"])
def test_a_wrong_name_is_caught(dotted):
    with pytest.raises((ImportError, AttributeError)):
        _resolve(dotted)
