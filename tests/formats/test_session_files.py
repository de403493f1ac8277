"""The session's file names are listed in one place (issue 49, rooms by idea): rangekit.formats.sessions.files.
No other module of rangekit, sim, drivers or calib writes one of them as a literal: not in a path, not in a
message or a help text (string constants, f-strings' text included; docstrings are prose for people, and
excluded). Tests may keep literals: they check the names from outside."""

import ast
import re
from pathlib import Path

from rangekit.formats.output_sets import OUTPUT_SETS
from rangekit.formats.sessions import files
from rangekit.formats.sessions.session import view_folder

ROOT = Path(__file__).resolve().parents[2]
SOURCE = ROOT / "rangekit" / "formats" / "sessions" / "files.py"
NAMES = re.compile(r"(?<![\w.\-])(" + "|".join(re.escape(n) for n in files.FILE_NAMES) + r")(?!\w)")
#: Modules that build a ``view_NNN`` name of something other than a session's view folder, and why.
OTHER_VIEWS = {"calib/camera.py": "a calibration's views, named in its report when no names are given"}


def _docstrings(tree: ast.AST) -> set[int]:
    return {id(node.body[0].value) for node in ast.walk(tree)
            if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body
            and isinstance(node.body[0], ast.Expr) and isinstance(node.body[0].value, ast.Constant)}


def literal_names(source: str) -> list[tuple[int, str]]:
    """``(line, text)`` of each string constant of ``source`` (docstrings excepted) naming a session file, or
    starting a view folder's name in an f-string (``f"view_{k:03d}"``)."""
    tree = ast.parse(source)
    docs = _docstrings(tree)
    found = [(node.lineno, node.value) for node in ast.walk(tree)
             if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docs
             and NAMES.search(node.value)]
    for node in ast.walk(tree):
        if isinstance(node, ast.JoinedStr):
            parts = node.values
            found += [(node.lineno, a.value) for a, b in zip(parts, parts[1:])
                      if isinstance(a, ast.Constant) and isinstance(b, ast.FormattedValue)
                      and str(a.value).endswith(files.VIEW_PREFIX)]
    return found


def _modules():
    for folder in ("rangekit", "sim", "drivers", "calib"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            rel = path.relative_to(ROOT)
            if "__pycache__" in rel.parts or (folder == "rangekit" and rel.parts[1] in ("sim", "drivers", "calib")):
                continue            # the symlinks of a worktree: those folders are walked as themselves
            yield rel.as_posix(), path


def test_no_module_but_the_one_source_names_a_session_file():
    hits = [f"{rel}:{line}: {text!r:.90}" for rel, path in _modules() if path != SOURCE
            for line, text in literal_names(path.read_text())
            if not (rel in OTHER_VIEWS and text.endswith(files.VIEW_PREFIX))]
    assert not hits, "session file names written as literals (take them from rangekit.formats.sessions.files):\n" \
        + "\n".join(hits)


def test_the_check_finds_a_literal_and_leaves_docstrings():
    source = ('"""Writes summary.json."""\n'
              'def f(out, k):\n'
              '    """Reads mesh.ply."""\n'
              '    (out / "poses.json").write_text("")\n'
              '    raise OSError(f"{out}: no session.json there")\n'
              '    return out / f"view_{k:03d}", "my-rig.json", "summary.jsonx"\n')
    assert sorted(line for line, _ in literal_names(source)) == [4, 5, 6]


def test_the_session_set_and_view_folders_come_from_the_list():
    session = next(s for s in OUTPUT_SETS if s.name == "session")
    assert session.members == files.SESSION_MEMBERS and session.markers == (files.SESSION_FILE,)
    assert view_folder("/s", 7) == Path("/s/view_007") and files.view_name(1234) == "view_1234"
    assert files.partial_view_folder("/s", 7) == Path("/s/view_007.partial")
    assert len(set(files.FILE_NAMES)) == len(files.FILE_NAMES)
    assert {getattr(files, n) for n in files.__all__ if n.endswith("_FILE")} == set(files.FILE_NAMES)
