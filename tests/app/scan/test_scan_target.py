"""``rangekit scan --target-mm`` and ``--patterns PRESET`` (issue 51 Deliver 2): the scan projects the set the
measured table picks, and records it so that a resumed scan keeps it."""

from __future__ import annotations

import json

import pytest

from rangekit.app.scan.options import ScanOptions
from rangekit.app.scan.setup import prepare_scan
from rangekit.cli import main
from rangekit.coded.patterns import PatternSpec
from rangekit.app.scan.presets import MEASURED, fastest_for, preset_spec
from rangekit.errors import OptionError


def _spec(tmp_path, **given) -> PatternSpec:
    setup = prepare_scan(ScanOptions(out=tmp_path / "s", object="sphere", process=False, **given))
    try:
        return setup.spec
    finally:
        setup.close()


def test_target_mm_gives_the_fastest_measured_set_that_meets_it(tmp_path):
    loose = max(max(r[0] for r in per.values()) for _, per in MEASURED.values())
    name = fastest_for(loose)
    assert _spec(tmp_path, target_mm=loose) == preset_spec(name, (1280, 800))
    assert _spec(tmp_path, patterns=name) == preset_spec(name, (1280, 800))
    # the default (issue 51): 48 frames, the Gray code of 8 px blocks + phase shift
    assert _spec(tmp_path) == preset_spec("hybrid-8step-min3", (1280, 800)) != PatternSpec("hybrid", 1280, 800)
    assert _spec(tmp_path, patterns="hybrid") == PatternSpec("hybrid", 1280, 800)   # the method's own options


@pytest.mark.parametrize("given, text", [
    ({"target_mm": 0.05, "patterns": "hybrid"}, "--target-mm 0.05 picks a new coded-light scan's patterns; "
                                                "--patterns names them too"),
    ({"target_mm": 0.05, "method": "laser"}, "--target-mm 0.05 picks a new coded-light scan's patterns; a laser"),
    ({"target_mm": 0.0001}, "--target-mm: expected a finite number in [0.001, 10] (mm)"),
    ({"target_mm": 0.001}, "--target-mm: no pattern set measured 0.001 mm RMS or better"),
])
def test_a_target_that_cannot_be_met_or_clashes_is_refused_by_its_flag(tmp_path, capsys, given, text):
    argv = ["scan", "--out", str(tmp_path / "s"), "--object", "sphere", "--no-process"]
    for key, value in given.items():
        argv += [{"target_mm": "--target-mm", "patterns": "--patterns", "method": "--method"}[key], str(value)]
    assert main(argv) == 2
    assert text in capsys.readouterr().err
    assert not (tmp_path / "s" / "session.json").exists()


def test_a_resumed_scan_keeps_its_preset_and_refuses_another(tmp_path):
    """A two-view scan of the sphere with the fewest-frame preset (18-30 frames a view): patterns.json holds the
    preset's spec, ``--resume`` with the same preset name is accepted, with another refused by name."""
    name = min(MEASURED, key=lambda n: MEASURED[n][0])
    out = tmp_path / "s"
    assert main(["-q", "scan", "--out", str(out), "--object", "sphere", "--views", "2", "--patterns", name,
                 "--no-process"]) == 0
    assert PatternSpec.from_dict(json.loads((out / "patterns.json").read_text())) == preset_spec(name, (1280, 800))
    assert main(["-q", "scan", "--resume", str(out), "--patterns", name, "--no-process"]) == 0
    other = next(n for n in MEASURED if n != name)
    with pytest.raises(OptionError, match=f"patterns {other!r} differs from the session"):
        prepare_scan(ScanOptions(resume=out, patterns=other, process=False))


def test_an_unknown_pattern_set_is_refused_by_its_flag_naming_the_sets(tmp_path, capsys):
    assert main(["scan", "--out", str(tmp_path / "s"), "--patterns", "fast", "--no-process"]) == 2
    err = capsys.readouterr().err
    assert "--patterns must be one of white, black, graycode" in err and "phase-3f-16px-3step" in err
    assert "found 'fast'" in err
