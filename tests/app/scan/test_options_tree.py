"""One options tree (issue 49, part 3): ``ScanOptions`` holds a ``ProcessOptions`` section, so everything ``rangekit
process`` can set ``rk.scan`` can set; each option's flag, range and default are written once (the dataclass field's
metadata) and read by the Python check, both command-line parsers and the web form; one error type names the field
from Python and the flag from the command line; summary.json records the options that made it; the laser branch
fuses with the same options."""

from __future__ import annotations

import argparse
import json
import shutil
from dataclasses import fields, replace

import pytest

import rangekit as rk
from rangekit._runtime.option_fields import default_of, specs
from rangekit.app.process.options import PROCESS_FLAGS, POISSON_DEFAULTS, ProcessOptions
from rangekit.app.scan.options import SCAN_DEFAULTS, SCAN_FLAGS, ScanOptions
from rangekit.cli.scan import BATCH_ONLY, process_options, scan_options
from rangekit.errors import OptionError, RangekitError
from rangekit.formats.sessions.summary import ProcessResult


def _parser(command: str) -> argparse.ArgumentParser:
    from rangekit.cli.run import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices[command]


COMMON = {"help", "verbose", "quiet"}     # every command's
#: A value other than the default of each ProcessOptions field, and the same on the command line (None: no flag).
OTHER = {"fusion": ("tsdf", ["--fusion", "tsdf"]), "method": ("ray-plane", None), "table_margin": (0.003, None),
         "report": (False, ["--no-report"]), "truth": (False, None), "mesh_format": ("obj", ["--format", "obj"]),
         "poisson_depth": (9, ["--poisson-depth", "9"]), "max_motion": (0.05, ["--max-motion", "5"]),
         "poisson_points": (500_000, None)}


def test_every_process_flag_is_reachable_from_rk_scan():
    """Walk ``rangekit process``'s flags: each (but the batch's own) is a ProcessOptions field, ``rangekit scan`` has
    the very same flag, and ``rk.scan`` sets the field through ``ScanOptions.processing``."""
    process, scan = _parser("process"), _parser("scan")
    scan_actions = {a.dest: a for a in scan._actions}
    flag_field = {flag: field for field, flag in PROCESS_FLAGS.items()}
    dests = [a for a in process._actions if a.dest not in COMMON | set(BATCH_ONLY)]
    assert dests
    for action in dests:
        field = flag_field[action.option_strings[0]]
        assert field in {f.name for f in fields(ProcessOptions)}
        twin = scan_actions[action.dest]      # defined once, shared: the same flag, type, choices and help
        same = (lambda a: (a.option_strings, getattr(a.type, "__name__", None), a.help, a.metavar))
        assert same(twin) == same(action)
        value = OTHER[field][0]
        options = ScanOptions(out="x", processing=ProcessOptions(**{field: value}))
        assert getattr(options.processing, field) == value
    assert set(OTHER) == {f.name for f in fields(ProcessOptions)}


def test_the_same_flags_make_the_same_processing_on_both_commands(tmp_path):
    argv = [x for _, cli in OTHER.values() if cli for x in cli]
    expected = ProcessOptions(**{f: v for f, (v, cli) in OTHER.items() if cli})
    scan_args = _parser("scan").parse_args(["--out", str(tmp_path / "s"), *argv])
    assert scan_options(scan_args).processing == expected
    assert process_options(_parser("process").parse_args([str(tmp_path / "s"), *argv])) == expected
    # no flag: the dataclass's defaults, the one place they are written
    assert process_options(_parser("process").parse_args([str(tmp_path / "s")])) == ProcessOptions()


def test_the_shorthands_fill_the_section_and_a_second_value_is_refused():
    old = ScanOptions(out="x", fusion="tsdf", report=False, format="stl")
    assert old == ScanOptions(out="x", processing=ProcessOptions(fusion="tsdf", report=False, mesh_format="stl"))
    assert (old.fusion, old.report, old.format) == (None, None, None)     # one source: the section
    assert replace(old, out=None, resume="x").processing == old.processing
    assert ScanOptions(out="x", fusion="tsdf", processing=ProcessOptions(fusion="tsdf")).processing.fusion == "tsdf"
    with pytest.raises(OptionError, match=r"^fusion 'tsdf' and processing\.fusion 'poisson': two values"):
        ScanOptions(out="x", fusion="tsdf", processing=ProcessOptions())
    with pytest.raises(OptionError, match=r"^processing: expected a ProcessOptions or None"):
        ScanOptions(out="x", processing={"fusion": "tsdf"})


@pytest.mark.parametrize("cls, name, command", [(ScanOptions, "views", "scan"), (ScanOptions, "steps", "scan"),
                                                (ScanOptions, "passes", "scan"), (ScanOptions, "seed", "scan"),
                                                (ProcessOptions, "poisson_depth", "process")])
def test_ranges_and_defaults_are_the_same_in_python_on_the_command_line_and_in_the_web_app(cls, name, command):
    from rangekit.ui.scan_options import option_limits

    s = specs(cls)[name]
    action = next(a for a in _parser(command)._actions if s.flag in a.option_strings)
    base = {"out": "x", "method": "laser"} if name == "steps" else {"out": "x"} if cls is ScanOptions else {}
    for value in (s.lo, s.hi):
        assert action.type(str(value)) == value
        cls(**base, **{name: value})
    for value in (s.lo - 1, s.hi + 1):
        with pytest.raises(argparse.ArgumentTypeError, match=rf"expected an integer in {s.lo}\.\.{s.hi}"):
            action.type(str(value))
        with pytest.raises(OptionError, match=rf"^{name}: expected an integer in {s.lo}\.\.{s.hi}"):
            cls(**base, **{name: value})
    web = option_limits()["scan" if cls is ScanOptions else "process"][name]
    assert (web["min"], web["max"], web["default"], web["flag"]) == (s.lo, s.hi, default_of(cls, name), s.flag)
    default = SCAN_DEFAULTS.get(name) if cls is ScanOptions else None
    assert web["default"] == default
    if default is not None:     # the help says it, read from the dataclass when shown (LazyHelp)
        from rangekit.cli._common import _load

        assert f"(default {default}" in action.help.format(**_load(action.help_values)())


def test_the_web_form_checks_the_views_with_the_command_line_s_range(tmp_path):
    from rangekit.ui.jobs.scan import ScanJob

    s = specs(ScanOptions)["views"]
    job = ScanJob(tmp_path, "sphere", None)
    for views in (s.lo - 1, s.hi + 1):
        with pytest.raises(RangekitError, match=rf"^views: expected a whole number {s.lo}-{s.hi}, found {views}$"):
            job.start("s", views)


def test_a_bad_option_names_the_field_from_python_and_the_flag_from_the_command_line():
    with pytest.raises(OptionError) as caught:
        ProcessOptions(poisson_depth=13)
    error = caught.value
    assert str(error).startswith("poisson_depth: expected an integer in 1..12")
    assert str(error.named(PROCESS_FLAGS)).startswith("--poisson-depth: expected an integer in 1..12")
    within = error.within("processing")    # as part of ScanOptions: its field, and rangekit scan's flag
    assert str(within).startswith("processing.poisson_depth: expected")
    assert str(within.named(SCAN_FLAGS)).startswith("--poisson-depth: expected")
    with pytest.raises(OptionError, match=r"^table_margin: expected a finite number in \[0, 1\) \(metres\)"):
        ProcessOptions(table_margin=1.0)
    with pytest.raises(OptionError) as caught:
        ProcessOptions(fusion="marching")
    assert str(caught.value.named(PROCESS_FLAGS)).startswith("--fusion: expected one of 'poisson', 'tsdf'")


def test_each_method_has_its_poisson_defaults():
    assert ProcessOptions().poisson(laser=False) == POISSON_DEFAULTS["coded"] == (8, 700_000)
    assert ProcessOptions().poisson(laser=True) == POISSON_DEFAULTS["laser"] == (9, 400_000)
    assert ProcessOptions(poisson_depth=7, poisson_points=50_000).poisson(laser=True) == (7, 50_000)


def test_summary_json_records_the_options_and_reads_back(tmp_path, reference_session):
    folder = shutil.copytree(reference_session, tmp_path / "s")
    options = ProcessOptions(report=False, max_motion=0.05)
    rk.process(folder, options)
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["options"] == options.to_dict() and summary["options"]["poisson_depth"] is None
    assert list(summary)[-1] == "options"     # the new entry last: every other key where it was
    assert ProcessOptions.from_dict(summary["options"]) == options
    result = ProcessResult.from_dict(summary, folder)
    assert result.options == options.to_dict() and result.view_errors is not None
    _close(result.to_dict(), summary)     # mm on disk, metres inside: equal to the last bits a unit change keeps
    older = {k: v for k, v in summary.items() if k != "options"}     # a summary.json without the entry
    assert ProcessResult.from_dict(older, folder).options is None


def _close(a, b, path="summary"):
    """``a`` and ``b`` the same JSON but for floats within 1e-12 relative."""
    if isinstance(a, float) and isinstance(b, float):
        assert a == pytest.approx(b, rel=1e-12, abs=1e-300), path
    elif isinstance(a, dict):
        assert isinstance(b, dict) and list(a) == list(b), path
        for k in a:
            _close(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            _close(x, y, f"{path}[{i}]")
    else:
        assert a == b, path


@pytest.fixture(scope="module")
def laser_session(tmp_path_factory):
    """A 6-step simulated laser session, acquired only."""
    from rangekit.cli import main

    out = tmp_path_factory.mktemp("laser_options") / "scan"
    assert main(["-q", "scan", "--method", "laser", "--steps", "6", "--out", str(out), "--no-process"]) == 0
    return out


def test_the_laser_branch_fuses_with_the_options_depth(tmp_path, laser_session):
    """``poisson_depth`` reaches the laser branch (it was fixed at 9): another depth, another mesh; left None, the
    laser's own 9."""
    vertices = {}
    for depth in (None, 9, 6):
        folder = shutil.copytree(laser_session, tmp_path / f"d{depth}")
        res = rk.process(folder, ProcessOptions(report=False, truth=False, poisson_depth=depth))
        assert res.options["poisson_depth"] == depth and res.laser.lasers[0].name == "laser0"
        vertices[depth] = res.mesh.vertices
        assert json.loads((folder / "summary.json").read_text())["laser"] == res.laser.to_dict()
    assert vertices[None] == vertices[9] != vertices[6]
    assert (tmp_path / "dNone" / "mesh.ply").read_bytes() == (tmp_path / "d9" / "mesh.ply").read_bytes()
