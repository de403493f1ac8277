"""Every command given a missing file, an empty file, random bytes or a folder where a file goes (or the
reverse) ends with exit 1 and one ``rangekit: error:`` line naming that input; nothing is written."""

from __future__ import annotations

import os

import pytest

from support.cli_runs import assert_error

KINDS = ("missing", "empty", "junk", "folder")
# Each command, with {} where the bad input goes; {json} and {png} are the same input with that suffix.
COMMANDS = {
    "render": ["render", "{}", "--out", "{out}/o.png"],
    "mesh": ["mesh", "{}", "--out", "{out}/o.ply"],
    "register": ["register", "{}", "{}", "--out", "{out}/reg"],
    "decode": ["decode", "{}", "--pattern", "graycode", "--projector", "64x32", "--out", "{out}/m.npz"],
    "reconstruct": ["reconstruct", "{}", "--out", "{out}/c.ply"],
    "tof": ["tof", "{}", "--out", "{out}/tof"],
    "stereo-images": ["stereo", "{png}", "{png}", "--rig", "{json}", "--out", "{out}/st"],
    "photometric": ["photometric", "{}", "--out", "{out}/ph"],
    "process": ["process", "{}"],
    "scan-resume": ["scan", "--resume", "{}", "--no-process"],
    "scan-rig": ["scan", "--rig", "{json}", "--out", "{out}/sc"],
    "calibrate-rig": ["calibrate", "--rig", "{json}", "--out", "{out}/rig.json"],
    "sim-object": ["sim", "render", "--object", "{}", "--out", "{out}/so"],
    "sim-rig": ["sim", "render", "--rig", "{json}", "--out", "{out}/sr"],
}


def _bad_input(folder, kind: str, suffix: str) -> str:
    path = folder / f"input{suffix}"
    if kind == "empty":
        path.write_bytes(b"")
    elif kind == "junk":
        path.write_bytes(os.urandom(3000))
    elif kind == "folder":
        path.mkdir()
    return str(path)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_a_bad_input_names_the_file(cli, tmp_path, command, kind):
    src, out = tmp_path / "in", tmp_path / "out"
    src.mkdir()
    out.mkdir()
    paths = {s: _bad_input(src, kind, s) for s in (".ply", ".json", ".png")}
    args = [a.format(paths[".ply"], json=paths[".json"], png=paths[".png"], out=out) for a in COMMANDS[command]]
    named = paths[".json"] if "{json}" in COMMANDS[command] else (
        paths[".png"] if "{png}" in COMMANDS[command] else paths[".ply"])
    run = cli(*args)
    assert_error(run, 1, os.path.basename(named))
    assert list(out.iterdir()) == []
