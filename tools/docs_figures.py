"""Rerun every figure quoted in README.md and docs/*.md and write the fresh output into the page.

A figure is a block of markdown between two HTML comments (invisible on GitHub):

    <!-- figure: python benchmarks/tof/bench_tof.py --markdown -->
    | ... the command's standard output, pasted here ... |
    <!-- /figure -->

The command is run by bash from the repo root, with ``.venv/bin`` first on PATH, ``PYTHONPATH`` set to
the repo and ``RANGEKIT_DOCS_WORK`` naming a scratch folder the figures of one run share (for example
one default scan that the README's summary and the report picture both read). Its standard output
replaces the block; its standard error (progress bars) is shown. A failing command leaves its block as
it was, is named at the end, and makes the exit status 1.

    make docs-figures                                         # every figure, a fresh scratch folder
    python tools/docs_figures.py --list                  # the figures and their commands
    python tools/docs_figures.py --only bench_tof        # the figures whose command has this text
    python tools/docs_figures.py --check                 # run, write nothing, name what changed

Figures of timing or memory change from run to run and machine to machine; the others (accuracy against
the simulator's truth, counts) are deterministic: after a run on a fresh clone, ``git diff docs README.md``
touches only timing lines and the report picture.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
START = re.compile(r"^<!-- figure: (?P<command>.+?) -->\s*$")
END = re.compile(r"^<!-- /figure -->\s*$")


@dataclass(frozen=True)
class Figure:
    """One block: its page, its rank on the page, the 0-based lines of its two markers, its command."""

    page: Path
    index: int
    start: int
    end: int
    command: str


def find_figures(page: Path) -> list[Figure]:
    """The figure blocks of one markdown page, in order; an unclosed or nested marker is an error."""
    lines = page.read_text().splitlines()
    figures, open_at, command = [], None, ""
    for i, line in enumerate(lines):
        match = START.match(line)
        if match:
            if open_at is not None:
                raise SystemExit(f"{page}:{i + 1}: a figure starts inside the figure opened at line {open_at + 1}")
            open_at, command = i, match["command"]
        elif END.match(line):
            if open_at is None:
                raise SystemExit(f"{page}:{i + 1}: '<!-- /figure -->' closes no figure")
            figures.append(Figure(page, len(figures), open_at, i, command))
            open_at = None
    if open_at is not None:
        raise SystemExit(f"{page}:{open_at + 1}: figure not closed (expected '<!-- /figure -->')")
    return figures


def pages() -> list[Path]:
    return [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]


def run_figure(figure: Figure, work: Path) -> str:
    """The command's standard output (the new block); raises RuntimeError with its error's tail."""
    env = dict(os.environ, PYTHONPATH=str(REPO), RANGEKIT_DOCS_WORK=str(work))
    env["PATH"] = f"{REPO / '.venv' / 'bin'}{os.pathsep}{env.get('PATH', '')}"
    done = subprocess.run(["bash", "-o", "pipefail", "-c", figure.command], cwd=REPO, env=env,
                          stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, stdin=subprocess.DEVNULL)
    sys.stderr.write(done.stderr[-4000:] if done.returncode else "")
    if done.returncode:
        raise RuntimeError(f"exit {done.returncode}: {done.stderr.strip().splitlines()[-1:] or ''}")
    if not done.stdout.strip():
        raise RuntimeError("printed nothing on standard output")
    return done.stdout.rstrip("\n")


def replace_block(page: Path, figure: Figure, text: str) -> bool:
    """Write ``text`` between the figure's markers (found again by rank: blocks above may have grown);
    True when it changed."""
    lines = page.read_text().splitlines()
    target = find_figures(page)[figure.index]
    old = lines[target.start + 1:target.end]
    new = text.splitlines()
    if old == new:
        return False
    lines[target.start + 1:target.end] = new
    page.write_text("\n".join(lines) + "\n")
    return True


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--list", action="store_true", help="list the figures and their commands, run nothing")
    parser.add_argument("--only", action="append", default=[], metavar="TEXT",
                        help="run only the figures whose command or page contains TEXT (repeatable)")
    parser.add_argument("--check", action="store_true", help="run, write nothing, name the blocks that differ")
    parser.add_argument("--keep-work", action="store_true",
                        help="reuse build/docs-figures (the shared scan) instead of starting it afresh")
    args = parser.parse_args(argv)

    figures = [f for page in pages() for f in find_figures(page)]
    if args.only:
        figures = [f for f in figures if any(t in f.command or t in f.page.name for t in args.only)]
    if args.list:
        for f in figures:
            print(f"{f.page.relative_to(REPO)}:{f.start + 1}  {f.command}")
        return 0
    work = REPO / "build" / "docs-figures"
    if work.exists() and not args.keep_work:
        shutil.rmtree(work)
    work.mkdir(parents=True, exist_ok=True)

    failed, changed = [], []
    for n, figure in enumerate(figures, 1):
        where = f"{figure.page.relative_to(REPO)}:{figure.start + 1}"
        print(f"[{n}/{len(figures)}] {where}  {figure.command}", file=sys.stderr, flush=True)
        t0 = time.perf_counter()
        try:
            text = run_figure(figure, work)
        except RuntimeError as exc:
            failed.append(f"{where}  {figure.command}: {exc}")
            continue
        if args.check:
            now = find_figures(figure.page)[figure.index]
            old = figure.page.read_text().splitlines()[now.start + 1:now.end]
            differs = old != text.splitlines()
        else:
            differs = replace_block(figure.page, figure, text)
        if differs:
            changed.append(where)
        print(f"    {'changed' if differs else 'unchanged'} ({time.perf_counter() - t0:.0f} s)", file=sys.stderr)
    print(f"{len(figures)} figures: {len(changed)} changed, {len(failed)} failed", file=sys.stderr)
    for line in changed:
        print(f"  changed: {line}", file=sys.stderr)
    for line in failed:
        print(f"  FAILED: {line}", file=sys.stderr)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
