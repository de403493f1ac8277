"""Frames written behind the capture: the same bytes, the same errors, the same crash safety."""

import errno
from types import SimpleNamespace

import numpy as np
import pytest

import rangekit.app.acquire.frame_writer as frame_writer
from rangekit.app.acquire.acquire import acquire
from rangekit.coded.patterns import make_pattern_spec
from rangekit.errors import DeviceDisconnected, StorageError
from rangekit.formats.sessions.session import ScanPlan, load_session
from rangekit.io import write_frame
from support.sessions import pngs, sim
from support.small_rigs import small_rig

SPEC = make_pattern_spec("graycode", (1280, 800))
PLAN = ScanPlan(n_views=3)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """An uninterrupted scan: the bytes every other run must give."""
    folder = tmp_path_factory.mktemp("ref") / "scan"
    acquire(sim(), small_rig(), SPEC, folder, plan=PLAN)
    return pngs(folder)


def test_a_full_disk_on_a_worker_names_the_frame_and_keeps_the_finished_views(tmp_path, monkeypatch, reference):
    def full_disk(path, image):           # view 1, frame 5
        if path.parent.name == "view_001.partial" and path.name == SPEC.frame_files[5]:
            raise OSError(errno.ENOSPC, "No space left on device", str(path))
        return write_frame(path, image)

    monkeypatch.setattr(frame_writer, "write_frame", full_disk)
    out = tmp_path / "scan"
    with pytest.raises(StorageError, match=r"view 1 \(turntable 120\.0 deg\), frame 5 \(.*\): writing: cannot "
                                           r"write .*view_001\.partial.*No space left.*rangekit scan --resume"):
        acquire(sim(), small_rig(), SPEC, out, plan=PLAN)
    assert [v.done for v in load_session(out).views] == [True, False, False]
    assert not list(out.glob("*.partial"))
    monkeypatch.undo()
    acquire(sim(), small_rig(), SPEC, out, plan=PLAN, resume=True)
    assert pngs(out) == reference


def test_the_error_named_is_the_earliest_frame_that_failed_whichever_thread_failed_first(tmp_path, monkeypatch):
    """Every frame of view 1 from frame 3 on fails, frame 3 last of all (it is slow): the error still names
    frame 3, as a one-thread writer would (CI once saw frame 1 named for a write cap that fails frame 0)."""
    import time

    def full_disk_from_frame_3(path, image):
        if path.parent.name == "view_001.partial" and path.name in SPEC.frame_files[3:]:
            if path.name == SPEC.frame_files[3]:
                time.sleep(0.5)           # the next frames fail first on the other thread
            raise OSError(errno.EFBIG, "File too large", str(path))
        return write_frame(path, image)

    monkeypatch.setattr(frame_writer, "write_frame", full_disk_from_frame_3)
    with pytest.raises(StorageError, match=r"view 1 \(turntable 120\.0 deg\), frame 3 \(.*\): writing: .*"
                                           + SPEC.frame_files[3] + ": File too large"):
        acquire(sim(), small_rig(), SPEC, tmp_path / "scan", plan=PLAN)


def test_ctrl_c_finishes_the_views_taken_and_the_resume_gives_the_same_bytes(tmp_path, reference):
    s = sim()
    real, taken = s.camera.capture_deferred, {"n": 0}

    def interrupted():
        taken["n"] += 1
        if taken["n"] == 2 * SPEC.n_frames + 3:    # view 2, frame 2: views 0 and 1 are still being written
            raise KeyboardInterrupt
        return real()

    s.camera.capture_deferred = interrupted
    out = tmp_path / "scan"
    with pytest.raises(KeyboardInterrupt):
        acquire(s, small_rig(), SPEC, out, plan=PLAN)
    assert [v.done for v in load_session(out).views] == [True, True, False]
    acquire(sim(), small_rig(), SPEC, out, plan=PLAN, resume=True)
    assert pngs(out) == reference


def test_a_frame_failing_to_render_on_a_worker_is_the_cameras_error(tmp_path):
    s = sim()
    real, taken = s.camera.capture_deferred, {"n": 0}

    def unplugged_later():
        taken["n"] += 1
        render = real()
        if taken["n"] != SPEC.n_frames + 2:
            return render

        def fail():
            raise DeviceDisconnected("camera (simulated): unplugged")
        return fail

    s.camera.capture_deferred = unplugged_later
    out = tmp_path / "scan"
    with pytest.raises(DeviceDisconnected, match=r"view 1 \(turntable 120\.0 deg\), frame 1 \(.*\): camera: "
                                                 r"camera \(simulated\): unplugged; 1 completed view"):
        acquire(s, small_rig(), SPEC, out, plan=PLAN)
    assert [v.done for v in load_session(out).views] == [True, False, False]
    assert not list(out.glob("*.partial"))


def test_a_camera_that_reuses_its_buffer_records_every_frame_as_taken(tmp_path, reference):
    """A hardware-style camera (no deferred capture) that returns the same array every time: each frame is
    copied when taken, so writing it later on a worker records the frame, not the next one."""
    s = sim()
    buffer = {}

    class ReusingCamera:
        calibration = s.camera.calibration

        def capture(self):
            image = s.camera.capture()
            if "img" not in buffer:
                buffer["img"] = image.copy()
            np.copyto(buffer["img"], image)
            return buffer["img"]

    devices = SimpleNamespace(camera=ReusingCamera(), projector=s.projector, turntable=s.turntable, sleep=s.sleep)
    out = tmp_path / "scan"
    acquire(devices, small_rig(), SPEC, out, plan=PLAN)
    assert pngs(out) == reference


def test_the_backlog_is_announced_when_the_capture_waits_and_when_it_caught_up(tmp_path):
    """With frames slower to write than to take, the writer says the capture is behind when max_pending frames
    wait (the capture blocks there), and that it caught up at half of them: once each way, in that order."""
    import threading

    gate = threading.Event()
    said = []
    writer = frame_writer.FrameWriter(workers=1, max_pending=4, on_load=lambda behind, n: said.append((behind, n)))
    image = np.zeros((4, 5), np.uint8)

    def slow():
        gate.wait(10)
        return image

    for i in range(4):
        writer.frame(0, 0.0, f"{i:03d}.png", f"frame {i}", tmp_path / f"{i:03d}.png", slow)
    assert said == []                         # full, but the capture has not waited yet
    taker = threading.Thread(target=writer.frame, args=(0, 0.0, "004.png", "frame 4", tmp_path / "004.png", slow))
    taker.start()
    taker.join(0.3)
    assert taker.is_alive() and said == [(True, 4)]   # the fifth frame waits for a slot
    gate.set()
    taker.join(10)
    writer.close()
    assert said[0] == (True, 4) and said[1][0] is False and said[1][1] <= 2 and len(said) == 2
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"{i:03d}.png" for i in range(5)]
