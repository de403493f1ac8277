"""Crash-safe acquisition on the simulated rig."""

import time

import numpy as np
import pytest

from rangekit.app.acquire.acquire import acquire
from rangekit.formats.sessions.session import ScanPlan, Session, SimulatorSettings, load_session
from rangekit.errors import ConfigError, DecodeError, DeviceDisconnected
from rangekit.coded.patterns import make_pattern_spec
from rangekit.sim import SimRig, default_scene
from support.sessions import pngs, sim
from support.small_rigs import small_rig



def test_unplug_then_resume_gives_identical_bytes(tmp_path):
    spec = make_pattern_spec("graycode", (1280, 800))
    plan = ScanPlan(n_views=4)
    acquire(sim(), small_rig(), spec, tmp_path / "a", plan=plan)
    rng = np.random.default_rng(7)
    fail_at = int(rng.integers(spec.n_frames, 3 * spec.n_frames))  # somewhere in views 1-2
    s = sim()
    s.inject_fault("camera", after=fail_at)
    with pytest.raises(DeviceDisconnected, match=r"view \d \(turntable .* deg\), frame \d+ \(.*\): camera: camera "
                                                 r"\(simulated\): unplugged.*resume") as exc:
        acquire(s, small_rig(), spec, tmp_path / "b", plan=plan)
    n_done = len(load_session(tmp_path / "b").done_views)
    assert n_done == fail_at // spec.n_frames
    # Every completed view is intact on disk, byte for byte.
    a = pngs(tmp_path / "a")
    b = pngs(tmp_path / "b")
    assert b and all(a[k] == v for k, v in b.items())
    print(f"\nunplugged at capture {fail_at}: {exc.value}")
    # Resume in a fresh process-equivalent rig: same bytes as the uninterrupted run.
    session = acquire(sim(), small_rig(), spec, tmp_path / "b", plan=plan, resume=True)
    assert all(v.done for v in session.views)
    assert pngs(tmp_path / "b") == a
    assert not list((tmp_path / "b").glob("*.partial"))


def test_session_folder_rules(tmp_path):
    spec = make_pattern_spec("white", (1280, 800))
    acquire(sim(), small_rig(), spec, tmp_path / "s", plan=ScanPlan(n_views=2))
    with pytest.raises(ConfigError, match="already holds a session"):
        acquire(sim(), small_rig(), spec, tmp_path / "s", plan=ScanPlan(n_views=2))
    with pytest.raises(ConfigError, match="another plan or pattern"):
        acquire(sim(), small_rig(), spec, tmp_path / "s", plan=ScanPlan(n_views=3), resume=True)
    with pytest.raises(ConfigError, match="no session.json to resume"):
        acquire(sim(), small_rig(), spec, tmp_path / "new", plan=ScanPlan(n_views=2), resume=True)
    # Resuming a complete session does nothing and changes nothing.
    before = pngs(tmp_path / "s")
    acquire(sim(), small_rig(), spec, tmp_path / "s", plan=ScanPlan(n_views=2), resume=True)
    assert pngs(tmp_path / "s") == before


class _DrivenTurntable:
    """The real Horus driver talking to the simulated board over a pty (scaled motion time); the
    simulator's scene follows the angle the board reports."""

    def __init__(self, driver, sim_turntable):
        self.driver, self.sim = driver, sim_turntable

    @property
    def angle(self):
        return self.driver.angle

    def rotate_to(self, angle):
        self.driver.rotate_to(angle)
        self.sim.rotate_to(self.driver.angle)


class _Devices:
    def __init__(self, camera, projector, turntable):
        self.camera, self.projector, self.turntable = camera, projector, turntable


@pytest.mark.slow
def test_twelve_view_scan_with_44_patterns_through_the_horus_driver(tmp_path):
    from rangekit.drivers.turntable import HorusTurntable
    from rangekit.sim.devices.firmware import start_firmware

    spec = make_pattern_spec("graycode", (1280, 800))
    s = SimRig(default_scene("lumpy"), seed=0)  # full 1280x1024 camera
    fw = start_firmware("horus", time_scale=0.05)  # 30 deg at 30 deg/s: 1 s, scaled to 0.05 s
    try:
        table = HorusTurntable(fw.port, timeout=2.0)
        devices = _Devices(s.camera, s.projector, _DrivenTurntable(table, s.turntable))
        t = time.perf_counter()
        session = acquire(devices, s.rig, spec, tmp_path / "full", plan=ScanPlan(n_views=12))
        secs = time.perf_counter() - t
        final_deg = fw.position_deg
        table.close()
    finally:
        fw.stop()
    print(f"\n12 views x 44 frames at 1280x1024, Horus driver on the simulated board (scaled time): "
          f"acquired and written in {secs:.1f} s")
    assert all(v.done for v in session.views)
    assert abs(final_deg - 330.0) < 360 / 3200  # the last view, to within a microstep


def test_session_records_the_camera_bit_depth_once(tmp_path):
    """A 12-bit camera saving 16-bit PNGs decodes with full scale 4095, not 65535; the bit depth comes
    from the rig file's capture.bits, recorded in session.json."""
    from dataclasses import replace

    from rangekit.io import read_png
    from rangekit.sim import ImagingModel

    spec = make_pattern_spec("white", (1280, 800))
    rig = replace(small_rig(), capture={"bits": 12})
    s = SimRig(default_scene("lumpy"), rig, imaging=ImagingModel(bits=12), seed=1)
    session = acquire(s, rig, spec, tmp_path / "s", plan=ScanPlan(n_views=2), hardware={"rig_file": "rig.json"})
    image = read_png(session.views[0].folder / "000.png")
    assert image.dtype == np.uint16 and 0 < image.max() <= 4095
    loaded = Session.load(tmp_path / "s")
    assert loaded.capture.bits == 12 and loaded.capture.full_scale == 4095.0
    assert loaded.capture.pattern_delay_s == 0.1 and loaded.hardware == {"rig_file": "rig.json"}
    # The simulator states its imaging model's depth in its rig file, so a simulated session records it too.
    assert SimRig(default_scene("lumpy"), small_rig(), imaging=ImagingModel(bits=12)).rig.capture["bits"] == 12


def test_sessions_written_before_capture_settings_still_load(tmp_path):
    import json

    spec = make_pattern_spec("white", (1280, 800))
    acquire(sim(), small_rig(), spec, tmp_path / "s", plan=ScanPlan(n_views=2),
            simulator=SimulatorSettings(object="lumpy", seed=3, imaging={"bits": 10}))
    path = tmp_path / "s" / "session.json"
    data = json.loads(path.read_text())
    del data["capture"]
    path.write_text(json.dumps(data))
    session = Session.load(tmp_path / "s")
    assert session.capture.full_scale == 1023.0 and session.simulator.object == "lumpy"
    assert [v.done for v in session.views] == [True, True]
    data["views"] = "all"
    path.write_text(json.dumps(data))
    with pytest.raises(ConfigError, match=r"session.json: views: expected a list of views .*, found 'all'"):
        Session.load(tmp_path / "s")


def test_a_12_bit_session_decodes_with_full_scale_4095(tmp_path):
    """The full scale processing uses is the session's (4095 for a 12-bit camera in 16-bit PNGs): with the
    PNG's 65535 the confidence threshold is 16x too high and most of the object is rejected."""
    from dataclasses import replace

    from rangekit.coded.reconstruct import reconstruct_view
    from rangekit.formats.capture import list_images, read_stack
    from rangekit.sim import ImagingModel

    rig = replace(small_rig(), capture={"bits": 12})
    s = SimRig(default_scene("lumpy"), rig, imaging=ImagingModel(bits=12), seed=1)
    spec = make_pattern_spec("graycode", s.projector.resolution)
    session = acquire(s, rig, spec, tmp_path / "s", plan=ScanPlan(n_views=2), hardware={"rig_file": "rig.json"})
    truth = s.ground_truth()  # the table at the last view's angle
    images = read_stack(list_images(session.views[-1].folder))
    assert images[0].dtype == np.uint16 and max(int(im.max()) for im in images) <= 4095
    loaded = Session.load(tmp_path / "s")
    # No margin around depth edges: this small camera's object is thin in pixels, and the test is the threshold.
    right = reconstruct_view(images, spec, rig.camera, rig.projector, full_scale=loaded.capture.full_scale,
                             edge_margin=0)
    try:
        n_wrong = int(reconstruct_view(images, spec, rig.camera, rig.projector, full_scale=65535.0,
                                       edge_margin=0).triangulated.valid.sum())
    except DecodeError:
        n_wrong = 0  # nothing survived
    lit = int((truth.lit & (truth.object_id == 0)).sum())  # the object (not the table)
    n_right = int(right.triangulated.valid.sum())
    print(f"\n12-bit view: {n_right} of {lit} lit pixels with full scale 4095, {n_wrong} with 65535")
    assert n_right >= 0.8 * lit
    assert n_wrong <= 0.5 * n_right
    # And the points it keeps are on the true surface.
    err = np.linalg.norm(right.triangulated.xyz[right.triangulated.valid] - truth.xyz[right.triangulated.valid], axis=1)
    assert np.median(err) < 5e-4
