"""The main job as one call: ``rk.scan(ScanOptions(...), on_event)`` is what ``rangekit scan`` runs; every flag
has its field and the reverse; a bad option names the field from Python and the flag from the command line;
processing reads each frame once and nothing it wrote."""

from __future__ import annotations

import argparse
import json
import shutil
from dataclasses import fields
from pathlib import Path

import pytest

import rangekit as rk
from support.sessions import N_VIEWS, frame_paths
from support.file_reads import FileReads
from rangekit.app import events as ev
from rangekit.app.process.options import PROCESS_FLAGS
from rangekit.app.scan.options import SCAN_FIELDS, SCAN_FLAGS, ScanOptions
from rangekit.cli import main
from rangekit.errors import OptionError, UsageError

FRAMES_GRAYCODE = 44  # the reference session's frames a view (graycode for a 1280-column projector)


def _scan_parser() -> argparse.ArgumentParser:
    from rangekit.cli.run import build_parser

    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return sub.choices["scan"]


def test_every_scan_flag_has_its_field_and_the_reverse():
    common = {"--help", "--verbose", "--quiet"}   # every command's
    flags = {s for a in _scan_parser()._actions for s in a.option_strings if s.startswith("--")} - common
    assert flags == set(SCAN_FLAGS.values())
    assert set(SCAN_FIELDS) == {f.name for f in fields(ScanOptions)}
    # Every field has its flag, but the section ``processing``, whose fields have theirs (rangekit process's).
    assert set(SCAN_FLAGS) == set(SCAN_FIELDS) - {"processing"} | {f"processing.{name}" for name in PROCESS_FLAGS}


def test_the_command_line_maps_each_flag_onto_its_field(tmp_path):
    from rangekit.cli.scan import scan_options

    argv = ["scan", "--out", str(tmp_path / "s"), "--rig", "sim", "--object", "bunny", "--views", "8",
            "--passes", "2", "--patterns", "graycode", "--seed", "3", "--up", "0", "1", "0", "--exposures", "2000",
            "8000", "--allow-auto-exposure", "--no-process", "--fusion", "tsdf", "--no-report", "--format", "obj"]
    options = scan_options(_scan_parser().parse_args(argv[1:]))
    assert options == ScanOptions(out=str(tmp_path / "s"), rig="sim", object="bunny", views=8, passes=2,
                                  patterns="graycode", seed=3, up=(0.0, 1.0, 0.0), exposures=(2000, 8000),
                                  allow_auto_exposure=True, process=False, fusion="tsdf", report=False, format="obj")


@pytest.mark.parametrize("given, field_text, flag_text", [
    ({"out": "x", "steps": 10, "views": 4}, "steps and views both give", "--steps and --views both give"),
    ({"out": "x", "method": "laser", "patterns": "hybrid"}, "patterns: a laser scan projects no patterns; leave "
     "patterns out with method laser", "--patterns: a laser scan projects no patterns; leave --patterns out with "
     "--method laser"),
    ({"out": "x", "views": 1}, "views: expected an integer in 2..720 or None, found 1", None),
    ({}, "out and resume: expected one of them", None),
    ({"out": "x", "format": "dxf"}, "format must be one of ply, obj, stl, glb, found 'dxf'", None),
])
def test_a_bad_option_names_the_field_and_on_the_command_line_the_flag(tmp_path, capsys, given, field_text,
                                                                       flag_text):
    with pytest.raises(OptionError) as caught:
        ScanOptions(**given)
    assert str(caught.value).startswith(field_text)
    assert isinstance(caught.value, UsageError)
    if flag_text is not None:
        argv = ["scan", "--no-process"] + [x for k, v in given.items() for x in
                                           ((SCAN_FLAGS[k], str(tmp_path / v)) if k == "out" else (SCAN_FLAGS[k], str(v)))]
        assert main(argv) == 2
        assert flag_text in capsys.readouterr().err


def test_the_call_acquires_what_the_command_acquires_with_every_view_announced(tmp_path):
    """A short simulated scan without processing: the same frames and session from Python as from the
    command line, each view announced once it is on disk."""
    options = dict(object="sphere", views=2, patterns="white", seed=1)
    assert main(["-q", "scan", "--out", str(tmp_path / "cli"), "--object", "sphere", "--views", "2", "--patterns",
                 "white", "--seed", "1", "--no-process"]) == 0
    seen: list = []
    res = rk.scan(ScanOptions(out=tmp_path / "call", process=False, **options), on_event=seen.append)
    assert res.processed is None and res.folder == tmp_path / "call" and len(res.session.done_views) == 2
    started = [e for e in seen if isinstance(e, ev.ScanStarted)]
    assert len(started) == 1 and (started[0].total, started[0].done, started[0].resume) == (2, 0, False)
    acquired = [e for e in seen if isinstance(e, ev.ViewAcquired)]
    assert [(e.index, e.total, e.folder.name) for e in acquired] == [(0, 2, "view_000"), (1, 2, "view_001")]
    assert seen.index(ev.StageStarted("acquire")) < seen.index(acquired[0])
    assert [type(e) for e in seen[-1:]] == [ev.StageFinished]
    for name in ("view_000/000.npy.zst", "view_001/000.npy.zst", "patterns.json", "rig.json"):
        assert (tmp_path / "cli" / name).read_bytes() == (tmp_path / "call" / name).read_bytes(), name
    cli, call = (json.loads((tmp_path / d / "session.json").read_text()) for d in ("cli", "call"))
    assert [v["sha256"] for v in cli["views"]] == [v["sha256"] for v in call["views"]]
    assert res.session.views == type(res.session).load(tmp_path / "call").views   # as on disk


def _watched(folder: Path) -> list[Path]:
    return [folder, *sorted(folder.glob("view_[0-9][0-9][0-9]"))]


def _check_reads(folder: Path, reads: FileReads, session_reads: int) -> None:
    """Each frame read once, session.json ``session_reads`` times, nothing processing wrote read back."""
    frames = [p.relative_to(folder).as_posix() for p in frame_paths(folder)]
    assert frames and {name: reads.count(name) for name in frames} == {name: 1 for name in frames}
    assert reads.count("session.json") == session_reads
    written = [p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file() and p.suffix not in (".png", ".zst")
               and p.name not in ("session.json", "rig.json", "patterns.json", "view.json", ".lock")]
    assert written and {name: reads.count(name) for name in written} == {name: 0 for name in written}


@pytest.mark.slow
def test_processing_reads_each_frame_once_and_nothing_it_wrote(tmp_session):
    """The small reference session processed from its folder (report included): session.json read once, each
    frame once (its SHA-256 taken from those bytes), no cache or output read back."""
    folder = tmp_session
    with FileReads(_watched(folder)) as reads:
        rk.process(folder)
    assert (folder / "report.html").is_file() and (folder / "view_000" / "maps.npz").is_file()
    _check_reads(folder, reads, session_reads=1)
    assert sum(n for name, n in reads.reads.items() if name.endswith(".png")) == N_VIEWS * FRAMES_GRAYCODE


def test_a_changed_frame_is_refused_from_the_bytes_read_for_decoding(tmp_session):
    from rangekit.errors import FileFormatError

    folder = tmp_session
    frame = folder / "view_002" / "005.png"
    data = bytearray(frame.read_bytes())
    data[-20] ^= 0xFF
    frame.write_bytes(bytes(data))
    with pytest.raises(FileFormatError, match=r"view_002: frame 005.png has changed: sha256 .* recorded"):
        rk.process(folder, rk.ProcessOptions(report=False))
    assert not (folder / "view_002" / "cloud.json").exists() and not (folder / "summary.json").exists()


@pytest.mark.slow   # two default scans (12 views at 1280x1024, processed): about 5 minutes; make test-slow runs it
def test_the_call_makes_the_files_of_the_command_and_reads_each_frame_once(tmp_path):
    """rk.scan(ScanOptions(out=..., object="lumpy")) against `rangekit scan --out ...`: the same meshes, poses,
    merged cloud and summary figures; the subscriber has every view's cloud before the fusion starts. Each view
    is decoded while the scan runs (rangekit.app.scan.streaming), its frames read once then; after acquisition
    the views still queued are decoded (their frames read once) and processing reads no frame, cache or output
    again: the decoded views are handed on."""
    by_call, by_cli = tmp_path / "call", tmp_path / "cli"
    seen: list = []
    watch: dict = {}

    def on_event(event) -> None:
        seen.append(event)
        if isinstance(event, ev.StageFinished) and event.stage == "acquire":
            watch["reads"] = FileReads(_watched(by_call)).__enter__()

    res = rk.scan(ScanOptions(out=by_call, object="lumpy"), on_event=on_event)
    watch["reads"].__exit__(None, None, None)
    reads = watch["reads"]
    frames = [p.relative_to(by_call).as_posix() for p in frame_paths(by_call)]
    assert frames and max(reads.count(name) for name in frames) <= 1
    written = [p.relative_to(by_call).as_posix() for p in by_call.rglob("*") if p.is_file() and p.suffix not in (".png", ".zst")
               and p.name not in ("session.json", "rig.json", "patterns.json", "view.json", ".lock")]
    assert written and not any(reads.count(name) for name in written)
    decoded = [e for e in seen if isinstance(e, ev.ViewDecoded)]
    assert [e.index for e in decoded] == list(range(12))
    assert max(seen.index(e) for e in decoded) < seen.index(ev.StageStarted("fuse"))
    kinds = [e.kind for e in seen if isinstance(e, ev.MeshReady)]
    assert kinds[:2] == ["preview", "observed"], kinds   # the preview first (issue 51: Memo.before_mesh)
    assert main(["-q", "scan", "--out", str(by_cli), "--object", "lumpy"]) == 0
    for name in ("mesh.ply", "mesh_watertight.ply", "merged.ply", "poses.json"):
        assert (by_call / name).read_bytes() == (by_cli / name).read_bytes(), name
    call, cli = (json.loads((d / "summary.json").read_text()) for d in (by_call, by_cli))
    call.pop("seconds"), cli.pop("seconds")
    assert json.loads(json.dumps(call).replace(str(by_call), "F")) == json.loads(json.dumps(cli).replace(str(by_cli), "F"))
    assert res.processed.accuracy.to_dict() == json.loads((by_call / "summary.json").read_text())["accuracy"]
    shutil.rmtree(by_cli)


def test_a_resumed_scan_announces_its_sessions_exposures(tmp_path):
    """ScanStarted says what every frame is taken at: a new multi-exposure scan its exposures, and resumed, the
    session's own (the options of a resumed scan leave them out)."""
    options = dict(object="sphere", views=2, patterns="white", process=False)
    first: list = []
    rk.scan(ScanOptions(out=tmp_path / "s", exposures=(8000, 2000), **options), on_event=first.append)
    again: list = []
    rk.scan(ScanOptions(resume=tmp_path / "s", process=False), on_event=again.append)
    (new,), (resumed,) = ([e for e in seen if isinstance(e, ev.ScanStarted)] for seen in (first, again))
    assert new.exposures_us == resumed.exposures_us == (2000, 8000)
    assert (resumed.resume, resumed.done, resumed.total) == (True, 2, 2)
    assert not [e for e in again if isinstance(e, ev.ViewAcquired)]
