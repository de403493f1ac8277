"""A scan whose object is knocked during a view (ScanOptions.sim_bump, the simulator's SimRig.inject_motion): the
view is found moved while the scan runs and taken again, and the mesh is the one of a scan with no knock; a
session whose knocked view was not taken again is refused by processing, naming the view (issue 38 item 3)."""

from __future__ import annotations

import json

import pytest

import rangekit as rk
from rangekit.app.events import Progress, ViewAcquired
from rangekit.app.scan.options import ScanOptions
from rangekit.errors import MotionError

pytestmark = pytest.mark.slow     # three views of the default rig at full size, twice (about a minute)

KNOCK = (1, 20, 0.5)              # view 1, from frame 20 (col_b1) on, 0.5 mm along x


def test_a_knocked_view_is_taken_again_and_the_mesh_is_the_still_scans(tmp_path):
    seen = []
    knocked = rk.scan(ScanOptions(out=tmp_path / "knocked", views=3, sim_bump=KNOCK, report=False),
                      on_event=seen.append)
    still = rk.scan(ScanOptions(out=tmp_path / "still", views=3, report=False))
    said = [e.message for e in seen if isinstance(e, Progress)]
    again = [line for line in said if "taking it again" in line]
    assert len(again) == 1 and again[0].startswith("view 1: ") and "col_b1" in again[0], again
    assert [e.index for e in seen if isinstance(e, ViewAcquired)] == [0, 1, 2, 1]      # view 1 once more
    # Taken again still, view 1 has the still scan's frames: the same mesh, to the byte.
    for name in ("mesh.ply", "poses.json"):
        assert (knocked.folder / name).read_bytes() == (still.folder / name).read_bytes(), name
    figures = [json.loads((f / "summary.json").read_text())["accuracy"]["rms"] for f in (knocked.folder, still.folder)]
    assert figures[0] == figures[1]


def test_a_session_with_a_knocked_view_is_refused_by_name(tmp_path):
    res = rk.scan(ScanOptions(out=tmp_path / "s", views=3, sim_bump=KNOCK, process=False))
    with pytest.raises(MotionError, match=r"view_001.*moved during the capture.*col_b1"):
        rk.process(res.folder)
    assert not (res.folder / "mesh.ply").exists()
    rk.process(res.folder, rk.ProcessOptions(max_motion=None, report=False))   # the user's call: not checked
    assert (res.folder / "mesh.ply").exists()
