"""The closed mesh held out of the space the views saw empty (issue 51 Deliver 4), on the small reference session
(4 views of the lumpy object, the small rig) against the simulator's truth.

The carving volume is made again here from what processing left on disk (each view's cached maps, the registered
poses: :func:`rangekit.app.process.carved.carved_space_of`), so the check of the closed mesh does not take the
processing's word for it.
"""

from __future__ import annotations

import pytest

from rangekit.app.acquire.acquire import acquire
from rangekit.app.process.carved import carved_space_of
from rangekit.app.process.process import process_session
from rangekit.app.scan.truth import session_evaluator
from rangekit.formats.meshes import load_mesh
from rangekit.coded.patterns import make_pattern_spec
from rangekit.formats.sessions.session import ScanPlan, Session, SimulatorSettings
from rangekit.sim import SimRig, default_scene
from rangekit.sim.scene.passes import pass_motions
from support.small_rigs import small_rig

#: The closed mesh's RMS where no view can see, on this session without the carving (main at bafb7ad, 4.93 mm).
UNCARVED_UNOBSERVED_RMS = 0.00493
#: The closed mesh's RMS of a two-pass scan (12 views), which processing did not carve (main at 5785366).
UNCARVED_TWO_PASS_RMS = 0.000339


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


@pytest.mark.slow
def test_a_two_pass_scan_carves_its_closed_mesh_too(tmp_path):
    """Both passes' views carve, each from its registered camera pose in the first pass's world (the rig, the
    table and each pixel's free depth are the same whichever way up the object stands; the first pass's table top
    is the floor): before, a scan turned over carved nothing and its closed mesh kept Poisson's guess."""
    scene, rig = default_scene("lumpy"), small_rig()
    sim = SimRig(scene, rig, seed=3, pass_motions=pass_motions(scene, rig, 2))
    settings = SimulatorSettings("lumpy", 3, pass_motions=tuple(tuple(map(tuple, m.tolist())) for m in sim.pass_motions))
    acquire(sim, rig, make_pattern_spec("graycode", (1280, 800)), tmp_path / "s", plan=ScanPlan(n_views=12, passes=2),
            simulator=settings)
    session = Session.load(tmp_path / "s")
    result = process_session(session, evaluate=session_evaluator(session))
    closed = load_mesh(tmp_path / "s" / "mesh_watertight.ply")
    closed_accuracy = result.accuracy.watertight
    print(f"\ntwo passes: closed mesh {closed_accuracy.rms_all * 1e3:.3f} mm RMS, {closed_accuracy.max * 1e3:.2f} mm "
          f"at most (uncarved {UNCARVED_TWO_PASS_RMS * 1e3:.3f} mm), where no view can see "
          f"{closed_accuracy.unobserved_rms * 1e3:.2f} mm")
    assert closed.is_watertight and closed.carved is not None and closed.carved.sum() > 0
    space = carved_space_of(session, load_mesh(tmp_path / "s" / "mesh.ply"))
    inside = space.depth_inside(closed.vertices)
    assert inside.max() <= space.voxel, f"{inside.max() * 1e3:.2f} mm inside carved space"
    print(f"{closed.carved.sum()} carved vertices; most inside carved space {inside.max() * 1e3:.2f} mm")
    assert closed_accuracy.rms_all < 0.9 * UNCARVED_TWO_PASS_RMS
