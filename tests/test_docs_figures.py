"""make docs-figures (tools/docs_figures.py): blocks are found, rerun and rewritten in place; a failing
command leaves its block and is named; unclosed markers are refused by line; every block in the repo's pages
is well formed and runs scripts that exist."""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
spec = importlib.util.spec_from_file_location("docs_figures", ROOT / "tools" / "docs_figures.py")
docs_figures = importlib.util.module_from_spec(spec)
sys.modules["docs_figures"] = docs_figures      # its dataclass looks its module up there
spec.loader.exec_module(docs_figures)

PAGE = """# Page

<!-- figure: printf '| a |\\n|---|\\n| 1 |\\n' -->
| a |
|---|
| 0 |
<!-- /figure -->

Text between.

<!-- figure: echo two; echo lines -->
old
<!-- /figure -->
"""


def test_blocks_are_rerun_and_written_in_place_even_when_an_earlier_one_grew(tmp_path):
    page = tmp_path / "page.md"
    page.write_text(PAGE)
    figures = docs_figures.find_figures(page)
    assert [f.command for f in figures] == ["printf '| a |\\n|---|\\n| 1 |\\n'", "echo two; echo lines"]
    for figure in reversed(figures):            # the second first, then the first: ranks, not line numbers
        assert docs_figures.replace_block(page, figure, docs_figures.run_figure(figure, tmp_path))
    text = page.read_text()
    assert "| 1 |" in text and "| 0 |" not in text and "two\nlines\n<!-- /figure -->" in text
    assert "Text between." in text and text.count("<!-- /figure -->") == 2
    assert not docs_figures.replace_block(page, docs_figures.find_figures(page)[1], "two\nlines")  # unchanged


def test_a_failing_command_raises_with_its_error_and_leaves_the_block(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("<!-- figure: echo partial; echo 'no such data' >&2; exit 3 -->\nkept\n<!-- /figure -->\n")
    figure = docs_figures.find_figures(page)[0]
    with pytest.raises(RuntimeError, match="exit 3.*no such data"):
        docs_figures.run_figure(figure, tmp_path)
    assert "kept" in page.read_text()


@pytest.mark.parametrize("text, message", [
    ("<!-- figure: echo a -->\nx\n", r"page.md:1: figure not closed"),
    ("x\n<!-- /figure -->\n", r"page.md:2: '<!-- /figure -->' closes no figure"),
    ("<!-- figure: echo a -->\n<!-- figure: echo b -->\n<!-- /figure -->\n", r"page.md:2: a figure starts inside"),
])
def test_broken_markers_are_named_by_line(tmp_path, text, message):
    page = tmp_path / "page.md"
    page.write_text(text)
    with pytest.raises(SystemExit, match=message):
        docs_figures.find_figures(page)


def test_the_repos_pages_have_well_formed_blocks_that_name_their_command():
    figures = [f for page in docs_figures.pages() for f in docs_figures.find_figures(page)]
    assert len(figures) >= 20
    assert any(f.page.name == "README.md" and "docs_scan.py summary" in f.command for f in figures)
    commands = [f.command for f in figures]
    assert all(c.startswith(("python benchmarks/", "python tools/")) for c in commands), commands
    scripts = {s for c in commands for s in re.findall(r"python ((?:benchmarks|tools)/\S+\.py)", c)}
    missing = [s for s in sorted(scripts) if not (ROOT / s).is_file()]
    assert scripts and not missing, f"figure commands run scripts that do not exist: {missing}"
