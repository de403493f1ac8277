"""rangekit check counts the frames a UVC driver queues (the flush frames), on the simulator.

The simulator's camera returns only frames exposed after the call, as a UVC webcam does not: :class:`QueuedCamera`
puts the kernel's V4L2 buffer queue in front of it (``depth`` buffers; when the application does not read, the
driver fills them with the frames exposed right after its last read and drops the newer ones), with the two reads
the uvc driver has: ``unflushed_frame`` (the queue's next frame) and ``capture`` (``flush_frames`` dropped first).
It models the queue only; the frames are the simulator's.
"""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from support.small_rigs import small_projector_rig

from rangekit.app.check.steps import measure_flush_frames, measure_latency, pattern_delay_for
from rangekit.sim import SimRig, default_scene


class QueuedCamera:
    """The simulator's camera behind a V4L2 buffer queue of ``depth`` frames (module docstring)."""

    def __init__(self, camera, depth: int, flush_frames: int = 0):
        self.camera, self.depth, self.flush_frames = camera, depth, flush_frames
        self.queue: list = []

    @property
    def calibration(self):
        return self.camera.calibration

    def unflushed_frame(self):
        frame = self.queue.pop(0) if self.queue else self.camera.capture()
        while len(self.queue) < self.depth:         # filled right after the read, whatever is shown then
            self.queue.append(self.camera.capture())
        return frame

    def capture(self):
        for _ in range(self.flush_frames):
            self.unflushed_frame()
        return self.unflushed_frame()


@pytest.fixture(scope="module")
def sim():
    return SimRig(default_scene("lumpy"), small_projector_rig(), seed=1, latency_s=0.05)


@pytest.mark.parametrize("depth", [0, 3])
def test_check_counts_the_queued_frames(sim, depth):
    cam = QueuedCamera(sim.camera, depth)
    devices = SimpleNamespace(camera=cam, projector=sim.projector, clock=sim.clock, sleep=sim.sleep)
    cam.flush_frames = depth + 1             # settled shots of the check itself must be fresh
    latency = max(measure_latency(devices, repeats=1))
    delay = pattern_delay_for(latency, 1 / 30)
    # The first white frame three 30 Hz frames after the projector (its 0.05 s latency to the next frame's
    # start); behind a queue, plus the frames the model's queue takes from the camera as it refills after the
    # read (a V4L2 driver fills it while the application waits; here it advances the virtual clock), whatever
    # the simulator's clock read when the test began (the tests of this module run on either worker, in any order).
    assert latency == pytest.approx(0.1 + depth / 30, abs=1e-9)
    assert measure_flush_frames(devices, delay, repeats=2) == (depth, depth)


def test_the_measured_flush_frames_go_into_a_uvc_rig_file_only(tmp_path):
    import json

    from rangekit.app.check.run import write_pattern_delay
    from rangekit.rig.rig_file import template_rig

    for camera, fields in (("uvc", ["capture.pattern_delay_s 0.1", "devices.camera.flush_frames 3"]),
                           ("depthai", ["capture.pattern_delay_s 0.1"])):
        path = tmp_path / f"{camera}.json"
        data = template_rig(camera=camera)
        path.write_text(json.dumps(data))
        assert write_pattern_delay(path, 0.1, 3) == fields
        new = json.loads(path.read_text())
        assert new["capture"].pop("pattern_delay_s") == 0.1
        if camera == "uvc":
            assert new["devices"]["camera"].pop("flush_frames") == 3
        data["capture"].pop("pattern_delay_s")
        data["devices"]["camera"].pop("flush_frames", None)
        assert new == data                      # no other field changed
