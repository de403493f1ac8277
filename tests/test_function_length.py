"""No function over 100 lines in the package (issue 49, deliverable 5): a long function is split by idea, each part
one idea with its docstring. A function's length is its lines from ``def`` to its last line, docstring and nested
functions included (a nested function is also measured on its own); methods are named by their class."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The folders measured: the package and the folders it installs as rangekit.sim, .drivers and .calib.
FOLDERS = ("rangekit", "sim", "drivers", "calib")
MAX_FUNCTION_LINES = 100
#: (module path, qualified name) of the functions allowed over the limit, each with why.
EXEMPT: set[tuple[str, str]] = set()


def long_functions(source: str, limit: int = MAX_FUNCTION_LINES) -> list[tuple[str, int]]:
    """``(qualified name, lines)`` of every function of ``source`` (Python text) longer than ``limit`` lines."""
    found: list[tuple[str, int]] = []

    def walk(node: ast.AST, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                name = prefix + child.name
                lines = child.end_lineno - child.lineno + 1
                if lines > limit:
                    found.append((name, lines))
                walk(child, name + ".<locals>.")
            elif isinstance(child, ast.ClassDef):
                walk(child, prefix + child.name + ".")
            else:
                walk(child, prefix)

    walk(ast.parse(source), "")
    return found


def _sources() -> list[Path]:
    # (A development checkout may link rangekit/sim -> ../sim: each source is read once, from its own folder.)
    return [p for folder in FOLDERS for p in sorted((ROOT / folder).rglob("*.py"))
            if "__pycache__" not in p.parts
            and not (folder == "rangekit" and p.relative_to(ROOT).parts[1] in FOLDERS)]


def test_no_function_is_over_100_lines():
    sources = _sources()
    assert len(sources) > 100 and ROOT / "rangekit/coded/decode.py" in sources   # the walk sees the package
    too_long, exempt_seen = [], set()
    for path in sources:
        module = path.relative_to(ROOT).as_posix()
        for name, lines in long_functions(path.read_text(encoding="utf-8")):
            if (module, name) in EXEMPT:
                exempt_seen.add((module, name))
            else:
                too_long.append(f"{module}:{name} ({lines} lines)")
    assert not too_long, (f"functions over {MAX_FUNCTION_LINES} lines (split each by idea, one idea a function "
                          "with its docstring): " + "; ".join(too_long))
    # An exemption whose function is gone or short again is dropped from EXEMPT.
    assert exempt_seen == EXEMPT, f"no longer over {MAX_FUNCTION_LINES} lines, remove from EXEMPT: {EXEMPT - exempt_seen}"


def _body(indent: str, n: int) -> str:
    return "".join(f"{indent}x{k} = {k}\n" for k in range(n))


def test_the_checker_finds_a_long_function():
    source = ("def short():\n    return 1\n\n\ndef long_one():\n" + _body("    ", 100) + "\n\nclass Job:\n"
              "    def run(self):\n" + _body("        ", 10) + "        def inner():\n" + _body("            ", 100)
              + "            return 0\n")
    assert long_functions(source) == [("long_one", 101), ("Job.run", 113), ("Job.run.<locals>.inner", 102)]
    assert long_functions("def f():\n" + _body("    ", 99)) == []      # 100 lines: not over
    assert long_functions("async def f():\n" + _body("    ", 100)) == [("f", 101)]
