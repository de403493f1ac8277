"""The closed mesh held out of the space the views saw empty (issue 51 Deliver 4), on the small reference session
(4 views of the lumpy object, the small rig) against the simulator's truth.

The carving volume is made again here from what processing left on disk (each view's cached maps, the registered
poses: :func:`rangekit.app.process.carved.carved_space_of`), so the check of the closed mesh does not take the
processing's word for it.
"""

from __future__ import annotations

from rangekit.app.process.carved import carved_space_of
from rangekit.app.process.process import process_session
from rangekit.app.scan.truth import session_evaluator
from rangekit.formats.meshes import load_mesh
from rangekit.formats.sessions.session import Session

#: The closed mesh's RMS where no view can see, on this session without the carving (main at bafb7ad, 4.93 mm).
UNCARVED_UNOBSERVED_RMS = 0.00493


def test_the_closed_mesh_keeps_out_of_carved_space(tmp_session):
    session = Session.load(tmp_session)
    result = process_session(session, evaluate=session_evaluator(session))
    closed = load_mesh(tmp_session / "mesh_watertight.ply")
    assert closed.is_watertight and closed.carved is not None     # the PLY's vertex property, read back
    # every vertex observed, carved or guessed: carved ones are never observed (4 views leave a loose hull: of
    # the 1825 unobserved vertices, 128 were carved, the rest a guess inside it)
    assert not (closed.carved & closed.observed).any()
    assert 0 < closed.carved.sum() < (~closed.observed).sum()
    space = carved_space_of(session, load_mesh(tmp_session / "mesh.ply"))
    inside = space.depth_inside(closed.vertices)
    assert inside.max() <= space.voxel, f"{inside.max() * 1e3:.2f} mm inside carved space"
    closed_accuracy = result.accuracy.watertight
    print(f"\nclosed mesh where no view can see: RMS {closed_accuracy.unobserved_rms * 1e3:.2f} mm (uncarved 4.93), "
          f"seen part {closed_accuracy.rms * 1e3:.3f} mm; {closed.carved.sum()} carved of "
          f"{(~closed.observed).sum()} unobserved vertices; most inside carved space {inside.max() * 1e3:.2f} mm")
    assert closed_accuracy.unobserved_rms < 0.95 * UNCARVED_UNOBSERVED_RMS
