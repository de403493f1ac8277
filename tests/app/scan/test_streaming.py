"""Processing while the scan runs (issue 36, rangekit.app.scan.streaming's steps on the runner's STREAMING worker,
rangekit.app.runner.StreamingWorker): each view decoded into the cache ``rangekit process`` reads, placed and
fused into a preview as it is acquired; the processing afterwards gives the same bytes as processing the session
from scratch; a resumed scan decodes nothing twice; in real time, a view is decoded before the next one's last
frame is taken; the worker backs off while the capture is behind.

Sessions: the small rig (320x256 camera), the lumpy object, Gray code (tests/support/sessions.py).
"""

from __future__ import annotations

import shutil
from dataclasses import asdict

import numpy as np
import pytest

from rangekit.app import events as ev
from rangekit.app.acquire.acquire import acquire
from rangekit.app.process.options import ProcessOptions
from rangekit.app.runner import StreamingWorker
from rangekit.app.scan.options import SCAN_FUSION
from rangekit.app.scan.streaming import StreamingViews
from rangekit.formats.sessions.files import PREVIEW_FILE
from rangekit.coded.patterns import make_pattern_spec
from rangekit.formats.sessions.session import CaptureSettings, ScanPlan, Session, SimulatorSettings
from rangekit.sim import ImagingModel
from support.sessions import N_VIEWS, copy_session, sim

CACHE = ("cloud.ply", "maps.npz", "cloud.json")
#: How the scan processes by default (its fusion: the blocks volume filled as the views come, issue 51).
SCANS = ProcessOptions(report=False, fusion=SCAN_FUSION)


def _acquire(out, devices, streaming, **kwargs):
    spec = make_pattern_spec("graycode", (1280, 800))
    return acquire(devices, devices.rig, spec, out, plan=ScanPlan(N_VIEWS),
                   simulator=SimulatorSettings("lumpy", 3, asdict(ImagingModel())), on_event=streaming.on_event,
                   **kwargs)


def _streaming(folder, on_event=None) -> StreamingWorker:
    """The scan's STREAMING placement of a session folder, as rangekit.app.scan.scan builds it."""
    return StreamingWorker(StreamingViews(folder, ProcessOptions(fusion=SCAN_FUSION), on_event))


def _cache(session_folder, index):
    return {name: (session_folder / f"view_{index:03d}" / name).read_bytes() for name in CACHE}


@pytest.fixture(scope="module")
def streamed(tmp_path_factory):
    """A session acquired with the streaming processor: (folder, the events, the preview's path, the decoded
    views handed to processing)."""
    out = tmp_path_factory.mktemp("streamed") / "s"
    seen = []
    streaming = _streaming(out, seen.append)
    _acquire(out, sim(), streaming)
    preview = streaming.finish()
    assert streaming.error is None
    return out, seen, preview, streaming.steps.results, streaming


def test_each_view_is_decoded_into_the_cache_processing_reads(streamed, tmp_path):
    """The cache the streaming processor writes is, byte for byte, what processing writes for the view."""
    from rangekit.app.process.view_cache import cache_settings, table_transform, view_cloud

    out, seen, _, _, _ = streamed
    assert [e.index for e in seen if isinstance(e, ev.ViewDecoded)] == list(range(N_VIEWS))
    fresh = copy_session(out, tmp_path / "fresh")
    for k in range(N_VIEWS):
        for name in CACHE:
            (fresh / f"view_{k:03d}" / name).unlink()
    session = Session.load(fresh)
    options = ProcessOptions()
    settings = cache_settings(session, options.method, options.table_margin)
    for view in session.done_views:
        view_cloud(view, session.pattern, session.rig, settings, session.capture.full_scale,
                   table_transform(session.rig), options.table_margin, session)
    for k in range(N_VIEWS):
        assert _cache(out, k) == _cache(fresh, k)


def test_views_are_placed_near_their_true_poses_and_the_preview_lies_on_the_object(streamed):
    """Each view's preview pose against the simulator's (the turntable's, exact) and the preview surface
    against the true surface: the turntable prior (exact here) refined by ICP stays within 0.05 deg and 0.05 mm; the
    preview's vertices within 0.3 mm RMS of the truth (measured 0.20 mm; a voxel of the preview grid is ~0.9 mm)."""
    import open3d as o3d

    from rangekit.formats.meshes import load_mesh
    from rangekit.metrology.pose_errors import pose_errors
    from rangekit.rig.rig_file import turntable_prior
    from rangekit.sim import default_scene

    out, seen, preview, _, _ = streamed
    placed = [e for e in seen if isinstance(e, ev.ViewPlaced)]
    assert [e.index for e in placed] == list(range(N_VIEWS))
    session = Session.load(out)
    truth = turntable_prior(session.rig.T_world_table, [v.angle for v in session.views])
    errors = pose_errors(np.stack([e.T_world_view for e in placed]), truth)
    assert errors.rotation_deg.max() < 0.05 and errors.translation_m.max() < 5e-5
    ready = [e for e in seen if isinstance(e, ev.MeshReady)]
    assert [e.kind for e in ready] == ["preview"] and ready[0].path == out / PREVIEW_FILE == preview
    mesh = load_mesh(preview)
    scene = o3d.t.geometry.RaycastingScene()
    true_mesh = default_scene("lumpy", with_table=False).world_mesh()      # view 0 is at turntable angle 0
    scene.add_triangles(o3d.core.Tensor(np.asarray(true_mesh.vertices, np.float32)),
                        o3d.core.Tensor(np.asarray(true_mesh.triangles, np.uint32)))
    d = scene.compute_distance(o3d.core.Tensor(np.asarray(mesh.vertices, np.float32))).numpy()
    rms = float(np.sqrt(np.mean(d ** 2)))
    print(f"\npreview: {len(mesh.vertices)} vertices, {rms * 1e3:.3f} mm RMS from the truth; poses within "
          f"{errors.rotation_deg.max():.4f} deg, {errors.translation_m.max() * 1e3:.4f} mm")
    assert len(mesh.triangles) > 1000 and rms < 3e-4


def test_the_final_view_goes_into_the_preview_before_its_cache_is_written(streamed):
    """The last view is decoded on the caller's thread (the worker starts none from its ViewAcquired on), placed
    and integrated, and the preview written before its cache (issue 51: the preview waits for nothing but the last
    view's decoding); the preview is announced once."""
    out, seen, preview, _, streaming = streamed
    last = N_VIEWS - 1
    order = [(type(e).__name__, getattr(e, "index", getattr(e, "kind", None))) for e in seen
             if isinstance(e, (ev.ViewPlaced, ev.ViewDecoded, ev.MeshStarted, ev.MeshReady))]
    assert (order.index(("ViewDecoded", last - 1)) < order.index(("ViewPlaced", last))
            < order.index(("MeshStarted", "preview")) < order.index(("MeshReady", "preview"))
            < order.index(("ViewDecoded", last))), order
    assert order.count(("MeshReady", "preview")) == 1
    assert preview.stat().st_mtime_ns <= (out / f"view_{last:03d}" / "cloud.json").stat().st_mtime_ns
    assert streaming.write_preview() == preview and order.count(("MeshReady", "preview")) == 1


def test_a_preview_that_cannot_be_written_leaves_the_views_steps_and_is_raised_by_write_preview(reference_session,
                                                                                                  tmp_path):
    """The final view writes the preview before its cache: a failure there (preview.ply a folder) does not stop the
    view's steps (its cache written, handed to the processing); the scan's own write_preview raises it."""
    folder = copy_session(reference_session, tmp_path / "s")
    for k in range(N_VIEWS):
        for name in CACHE:
            (folder / f"view_{k:03d}" / name).unlink(missing_ok=True)
    (folder / PREVIEW_FILE).mkdir()
    streaming = _streaming(folder)
    streaming.on_event(ev.ScanStarted(folder, N_VIEWS, 0, 60, False, None, False))
    for k in range(N_VIEWS):
        streaming.on_event(ev.ViewAcquired(k, N_VIEWS, folder / f"view_{k:03d}", 0.0, 60))
    streaming.drain()
    assert streaming.error is None and streaming.steps.decoded == list(range(N_VIEWS))
    assert all((folder / f"view_{k:03d}" / "cloud.json").is_file() for k in range(N_VIEWS))
    with pytest.raises(OSError):
        streaming.write_preview()


def test_a_view_the_worker_is_on_when_the_last_is_acquired_leaves_the_rest_of_its_steps_to_the_scan(
        reference_session, tmp_path):
    """The last view acquired while the worker is on view N-2 (held after its decode by its ViewDecoded's
    subscriber): the worker starts nothing more, and view N-2's ICP placing, free depth and registration ahead wait
    for the preview (its placing by the prior, its work ahead in last_ahead, on the scan's thread), as a last
    view's; the processing gives the bytes ``rangekit process`` writes."""
    import threading

    from rangekit.app.scan.scan import _preview_then_process, process

    scanned, fresh = copy_session(reference_session, tmp_path / "scanned"), copy_session(reference_session,
                                                                                         tmp_path / "fresh")
    for folder in (scanned, fresh):
        for k in range(N_VIEWS):
            for name in CACHE:
                (folder / f"view_{k:03d}" / name).unlink(missing_ok=True)
    decoded, gate = threading.Event(), threading.Event()

    def on_event(event):
        if isinstance(event, ev.ViewDecoded) and event.index == N_VIEWS - 2:
            decoded.set()
            gate.wait(120)

    streaming = _streaming(scanned, on_event)
    streaming.on_event(ev.ScanStarted(scanned, N_VIEWS, 0, 60, False, None, False))
    for k in range(N_VIEWS - 1):
        streaming.on_event(ev.ViewAcquired(k, N_VIEWS, scanned / f"view_{k:03d}", 0.0, 60))
    assert decoded.wait(300)
    streaming.on_event(ev.ViewAcquired(N_VIEWS - 1, N_VIEWS, scanned / f"view_{N_VIEWS - 1:03d}", 0.0, 60))
    gate.set()
    streaming.drain()
    steps = streaming.steps
    assert streaming.error is None and steps.decoded == list(range(N_VIEWS))
    assert sorted(steps.free) == list(range(N_VIEWS - 2)) and N_VIEWS - 2 not in steps.registration.views
    options = ProcessOptions(report=False)
    _preview_then_process(streaming, Session.load(scanned), options, None)
    assert sorted(steps.free) == list(range(N_VIEWS)) and (scanned / PREVIEW_FILE).is_file()
    process(fresh, options)
    for name in ("mesh.ply", "mesh_watertight.ply", "merged.ply", "poses.json"):
        assert (scanned / name).read_bytes() == (fresh / name).read_bytes(), name


def test_a_resumed_scan_decodes_nothing_twice(streamed, tmp_path):
    """Views 0 and 1 streamed, the scan stopped; resumed, the streaming processor takes the done views from their
    cache (files untouched) and decodes only views 2 and 3."""
    out, _, _, _, _ = streamed
    part = copy_session(out, tmp_path / "part", pending=(2, 3))
    before = {k: {n: (part / f"view_{k:03d}" / n).stat().st_mtime_ns for n in CACHE} for k in (0, 1)}
    seen = []
    streaming = _streaming(part, seen.append)
    streaming.on_event(ev.ScanStarted(part, N_VIEWS, 2, 44, True, None, False))
    _acquire(part, sim(), streaming, resume=True)
    streaming.finish()
    assert streaming.error is None and sorted(streaming.steps.decoded) == [0, 1, 2, 3]
    after = {k: {n: (part / f"view_{k:03d}" / n).stat().st_mtime_ns for n in CACHE} for k in (0, 1)}
    assert after == before
    for k in (2, 3):
        assert _cache(part, k) == _cache(out, k)


@pytest.mark.slow
def test_the_final_mesh_is_what_rangekit_process_makes(streamed, tmp_path):
    """Processing after the streamed scan, given what the scan did while its views came (the decoded views, the
    registration's levels and first-round pairs, each view's errors against the truth) or reading the views from
    their cache, writes the bytes ``rangekit process`` writes for the same session without any cache; and takes
    the work ahead (every level, every first-round pair, the errors of the views decoded while the capture ran)."""
    import json

    from rangekit.app.process.process import process_session
    from rangekit.app.runner import Plan
    from rangekit.app.scan.scan import process

    out, _, _, results, streaming = streamed
    memo = streaming.memo()
    ahead, evaluate = memo.registration, memo.evaluate
    assert ahead is not None and ahead.views == list(range(N_VIEWS)) and evaluate is not None
    assert sorted(memo.free) == list(range(N_VIEWS))   # each view's free depth (the carving's), made as it came
    scanned = shutil.copytree(out, tmp_path / "scanned")
    cached = shutil.copytree(out, tmp_path / "cached")
    fresh = copy_session(out, tmp_path / "fresh")
    for k in range(N_VIEWS):
        for name in CACHE:
            (fresh / f"view_{k:03d}" / name).unlink()
    process_session(scanned, SCANS, evaluate=evaluate, plan=Plan.STREAMING, memo=memo)
    assert memo.blocks.taken and memo.blocks.views == list(range(N_VIEWS))   # the volume filled as views came
    # the errors of the views decoded while the capture ran (not the last one's: the processing measures it
    # once mesh.ply is written, Memo.truth_after_mesh)
    assert ahead.taken == {"levels": 2, "pairs": len(ahead._jobs), "overlaps": len(ahead._joint),
                           "matches": len(ahead._matches)} and len(ahead._matches) > 0
    measured = streaming.steps.measured
    # how many the worker measured depends on how far it got while the capture ran (none when the capture outran it,
    # e.g. beside the blocks volume's child starting: the views then drained, measured by the processing);
    # test_the_mesh_is_the_same_whichever_views_the_worker_took_before_the_acquisition_ended forces the split
    assert evaluate.views_taken == len(measured) and N_VIEWS - 1 not in measured
    process(cached, SCANS)
    process(fresh, SCANS)
    for name in ("mesh.ply", "mesh_watertight.ply", "merged.ply", "poses.json"):
        assert (scanned / name).read_bytes() == (fresh / name).read_bytes() == (cached / name).read_bytes(), name

    def figures(folder):   # summary.json but its seconds
        d = json.loads((folder / "summary.json").read_text())
        d.pop("seconds", None)
        return d

    assert figures(scanned) == figures(fresh) == figures(cached)
    assert figures(fresh)["view_errors"] is not None


@pytest.mark.parametrize("on_worker", [0, 1, N_VIEWS - 1])
def test_the_mesh_is_the_same_whichever_views_the_worker_took_before_the_acquisition_ended(streamed, tmp_path,
                                                                                             on_worker):
    """What a scan does after its acquisition, with the split between the streaming worker (views decoded, placed
    and worked ahead on its thread while the capture runs) and the drain (the views left: decoded on the scan's
    thread, their work ahead beside the preview, ``StreamingViews.last_ahead``) forced: the first ``on_worker``
    views through the worker, the rest drained, as a resumed or loaded scan splits them. Whatever the split, the
    meshes, poses and figures are the bytes ``rangekit process`` writes (issue 51: a resumed scan under load once
    wrote other bytes than its uninterrupted twin)."""
    import json
    import time

    from rangekit._runtime.executor import Where, start
    from rangekit.app.runner import Plan
    from rangekit.app.scan.scan import _process, _waiting, process

    out = streamed[0]
    scanned, fresh = copy_session(out, tmp_path / "scanned"), copy_session(out, tmp_path / "fresh")
    for folder in (scanned, fresh):
        for k in range(N_VIEWS):
            for name in CACHE:
                (folder / f"view_{k:03d}" / name).unlink(missing_ok=True)
    options = SCANS
    worker = _streaming(scanned)
    for k in range(on_worker):
        worker.on_event(ev.ViewAcquired(k, N_VIEWS, str(scanned / f"view_{k:03d}"), 0.0, 1))
    while len(worker.steps.measured) < on_worker and worker.error is None:   # the worker's views, on its thread,
        # through all their steps (their errors measured ahead last): else the hand-over at the last view's
        # acquisition leaves the one it is on to the drain
        time.sleep(0.01)
    for k in range(on_worker, N_VIEWS):
        worker.on_event(ev.ViewAcquired(k, N_VIEWS, str(scanned / f"view_{k:03d}"), 0.0, 1))
    worker.drain()
    assert worker.error is None and worker.steps.decoded == list(range(N_VIEWS))
    with start(Where.HERE, worker.write_preview) as preview:   # as rangekit.app.scan.scan._preview_then_process
        with start(Where.THREAD, worker.finish_blocks) as blocks:
            memo = worker.memo()
            memo.before_mesh = _waiting(blocks)
            _process(Session.load(scanned), options, None, Plan.STREAMING, memo)
        assert preview.result() is not None
    assert sorted(memo.free) == list(range(N_VIEWS)) and memo.registration.taken["matches"] > 0
    assert memo.blocks.taken and memo.blocks.views == list(range(N_VIEWS))
    assert worker.steps.measured == list(range(on_worker))   # the worker's views' errors measured ahead, in order
    process(fresh, options)
    for name in ("mesh.ply", "mesh_watertight.ply", "merged.ply", "poses.json"):
        assert (scanned / name).read_bytes() == (fresh / name).read_bytes(), name

    def figures(folder):   # summary.json but its seconds
        d = json.loads((folder / "summary.json").read_text())
        d.pop("seconds", None)
        return d

    assert figures(scanned) == figures(fresh)


@pytest.mark.slow
def test_in_real_time_a_view_is_decoded_before_the_next_ones_last_frame(tmp_path):
    """The simulated rig on the wall clock (a 20 ms pattern delay, 30 frames a second, the turntable at its
    real-time speed): each view's ViewDecoded comes before the next view's ViewAcquired (sent once that view's
    last frame is on disk), so processing keeps up with the capture; each view's TSDF integrations (the preview's,
    the blocks fusion's) started in one of the capture's waits (rangekit.app.acquire.quiet); the last view's frames were read while it was taken."""
    from rangekit.sim import SimRig, default_scene
    from rangekit.sim.devices.realtime import realtime_options
    from support.small_rigs import small_rig

    devices = SimRig(default_scene("lumpy"), small_rig(), seed=3, **realtime_options(0.02))
    order = []
    streaming = _streaming(tmp_path / "s", order.append)
    integrations = []     # each TSDF integration's wait for a quiet window of the capture: went in one (True)

    class Recorded(type(streaming.steps.quiet)):
        def wait(self, need_s, timeout_s=1.0):
            ok = super().wait(need_s, timeout_s)
            integrations.append(ok)
            return ok
    streaming.steps.quiet = Recorded()

    def on_event(event):
        streaming.on_event(event)
        order.append(event)

    spec = make_pattern_spec("graycode", (1280, 800))
    acquire(devices, devices.rig, spec, tmp_path / "s", plan=ScanPlan(3),
            capture=CaptureSettings(bits=8, pattern_delay_s=0.02, turntable_settle_s=0.05),
            simulator=SimulatorSettings("lumpy", 3, asdict(ImagingModel())), on_event=on_event, quiet=streaming.steps.quiet)
    streaming.finish()
    # each view's preview integration and, but the last's (integrated once the preview is written), its blocks
    # fusion's: none waited out its timeout
    assert len(integrations) == 3 + 2 and all(integrations), integrations
    names = [(type(e).__name__, e.index) for e in order if isinstance(e, (ev.ViewAcquired, ev.ViewDecoded))]
    print(f"\n{names}")
    for k in range(2):
        assert names.index(("ViewDecoded", k)) < names.index(("ViewAcquired", k + 1)), names
    # the last view's frames were read as the capture wrote them (StreamingViews.prefetch; its bytes:
    # tests/app/scan/test_prefetch.py)
    assert streaming.steps.read_ahead.get(2, 0) > 0, streaming.steps.read_ahead


def test_no_view_is_started_while_the_capture_is_behind(reference_session, tmp_path):
    """Back-off: after CaptureLoad(behind=True) a queued view waits; CaptureLoad(behind=False) (or the end of the
    acquisition) lets it go."""
    import time

    folder = copy_session(reference_session, tmp_path / "s")
    streaming = _streaming(folder)
    streaming.on_event(ev.ScanStarted(folder, N_VIEWS, 0, 60, False, None, False))
    streaming.on_event(ev.CaptureLoad(True, 64))
    streaming.on_event(ev.ViewAcquired(0, N_VIEWS, folder / "view_000", 0.0, 60))
    time.sleep(0.5)
    assert streaming.steps.decoded == [] and streaming.paused == 1
    streaming.on_event(ev.CaptureLoad(False, 32))
    streaming.on_event(ev.CaptureLoad(True, 64))
    streaming.on_event(ev.ViewAcquired(1, N_VIEWS, folder / "view_001", 0.0, 60))
    deadline = time.monotonic() + 60
    while streaming.paused < 2 and time.monotonic() < deadline:
        time.sleep(0.05)
    time.sleep(0.3)
    assert streaming.steps.decoded == [0] and streaming.paused == 2   # view 0 went when the capture caught up; view 1 waits
    streaming.finish()                       # the acquisition is over: the rest goes
    assert streaming.error is None and streaming.steps.decoded == [0, 1]
