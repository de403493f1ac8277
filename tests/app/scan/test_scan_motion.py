"""A scan whose object is knocked during a view (ScanOptions.sim_bump, the simulator's SimRig.inject_motion): the
view is found moved while the scan runs and taken again, and the mesh is the one of a scan with no knock; a
session whose knocked view was not taken again is refused by processing, naming the view (issue 38 item 3). The
60-frame ``hybrid`` knocked from col_b1 (its frames named), and the default ``hybrid-8step-min3`` knocked during its
column phase frames, which only its check of the Gray blocks against the phase sees (issue 51)."""

from __future__ import annotations

import json

import pytest

import rangekit as rk
from rangekit.app.events import Progress, ViewAcquired
from rangekit.app.scan.options import ScanOptions
from rangekit.errors import MotionError

pytestmark = pytest.mark.slow     # three views of the default rig at full size, twice (about a minute)

#: (patterns, knock: view 1 from this frame on, 0.5 mm along x, what the refusal names): the 60-frame hybrid from
#: frame 20 (col_b1), the default 48 frames from frame 32 (col_p16_s0, the first column phase frame: 16% of the
#: pixels flagged; the column and row phase frames named).
KNOCKS = [pytest.param("hybrid", (1, 20, 0.5), "col_b1", id="hybrid-60"),
          pytest.param(None, (1, 32, 0.5), "frames after: col_p16_s0", id="default-48")]


@pytest.mark.parametrize("patterns, knock, named", KNOCKS)
def test_a_knocked_view_is_taken_again_and_the_mesh_is_the_still_scans(tmp_path, patterns, knock, named):
    seen = []
    knocked = rk.scan(ScanOptions(out=tmp_path / "knocked", views=3, patterns=patterns, sim_bump=knock,
                                  report=False), on_event=seen.append)
    still = rk.scan(ScanOptions(out=tmp_path / "still", views=3, patterns=patterns, report=False))
    said = [e.message for e in seen if isinstance(e, Progress)]
    again = [line for line in said if "taking it again" in line]
    assert len(again) == 1 and again[0].startswith("view 1: ") and named in again[0], again
    assert [e.index for e in seen if isinstance(e, ViewAcquired)] == [0, 1, 2, 1]      # view 1 once more
    # Taken again still, view 1 has the still scan's frames: the same mesh, to the byte.
    for name in ("mesh.ply", "poses.json"):
        assert (knocked.folder / name).read_bytes() == (still.folder / name).read_bytes(), name
    figures = [json.loads((f / "summary.json").read_text())["accuracy"]["rms"] for f in (knocked.folder, still.folder)]
    assert figures[0] == figures[1]


@pytest.mark.parametrize("patterns, knock, named", KNOCKS)
def test_a_session_with_a_knocked_view_is_refused_by_name(tmp_path, patterns, knock, named):
    res = rk.scan(ScanOptions(out=tmp_path / "s", views=3, patterns=patterns, sim_bump=knock, process=False))
    with pytest.raises(MotionError, match=rf"view_001.*moved during the capture.*{named}"):
        rk.process(res.folder)
    assert not (res.folder / "mesh.ply").exists()
    rk.process(res.folder, rk.ProcessOptions(max_motion=None, report=False))   # the user's call: not checked
    assert (res.folder / "mesh.ply").exists()
