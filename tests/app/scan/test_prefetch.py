"""The scan's last view read ahead while it is taken (rangekit.app.scan.streaming.StreamingViews.prefetch, issue 51:
the preview within 1 s of the last frame): the frames on disk so far decoded into the view's stack, only the rest
read once its last frame is written; the view's cache is the same bytes as decoding it from scratch, also when the
frames read ahead are not the ones recorded (a view taken again) or are all of them.

The reference session (tests/support/sessions.py: 4 views, the small rig, Gray code); its last view's folder is
made its ``.partial`` folder with some of its frames, as during the capture."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from rangekit.app import events as ev
from rangekit.app.process.options import ProcessOptions
from rangekit.app.process.view_cache import cache_settings, table_transform, view_cloud
from rangekit.app.scan.streaming import StreamingViews
from rangekit.formats.capture import list_images
from rangekit.formats.sessions.files import partial_view_folder, view_folder
from rangekit.formats.sessions.session import Session
from support.sessions import copy_session

CACHE = ("cloud.ply", "maps.npz", "cloud.json")


def _fresh(reference_session, dest: Path) -> Path:
    """A copy of the session without the views' caches."""
    out = copy_session(reference_session, dest)
    for name in CACHE:
        for path in out.glob(f"view_*/{name}"):
            path.unlink()
    return out


def _cache(folder: Path, k: int) -> dict:
    return {name: (view_folder(folder, k) / name).read_bytes() for name in CACHE}


@pytest.fixture(scope="module")
def expected(reference_session, tmp_path_factory):
    """The last view's cache decoded from scratch, as ``rangekit process`` writes it: (folder, its index)."""
    out = _fresh(reference_session, tmp_path_factory.mktemp("prefetch") / "fresh")
    session = Session.load(out)
    options, k = ProcessOptions(), len(session.views) - 1
    view_cloud(session.views[k], session.pattern, session.rig, cache_settings(session, options.method,
               options.table_margin, options.max_motion), session.capture.full_scale, table_transform(session.rig),
               options.table_margin, session)
    return out, k


@pytest.mark.parametrize("taken", ["some", "all", "retaken"])
def test_the_last_views_frames_read_ahead_give_the_cache_decoding_from_scratch_gives(reference_session, expected,
                                                                                     tmp_path, taken):
    """``some``: 5 frames on disk while it is taken (the rest read after its last frame, into the stack's tail);
    ``all``: every frame read ahead (none read after); ``retaken``: the frames read ahead were another capture's
    (view 0's: the view taken again after a fault), so every frame is read again. The view before it is decoded
    after the reading began (the worker a view behind): what was read is kept for the last view."""
    out = _fresh(reference_session, tmp_path / "s")
    fresh, k = expected
    steps = StreamingViews(out, ProcessOptions())
    for j in range(k - 1):
        steps.view(j)
    final, partial = view_folder(out, k), partial_view_folder(out, k)
    frames = list_images(final)
    held = tmp_path / "held"
    held.mkdir()
    source = view_folder(out, 0) if taken == "retaken" else final
    partial.mkdir()
    for path in list_images(source)[:len(frames) if taken == "all" else 5]:   # what the capture wrote so far
        shutil.copy2(path, partial / path.name)
    assert steps.views_of(ev.ViewAcquired(k - 1, k + 1, view_folder(out, k - 1), 0.0, len(frames))) == [k - 1]
    assert steps.prefetch() is not None
    read = steps._frames.have()
    assert read is not None and len(read[1]) == (len(frames) if taken == "all" else 5)
    steps.view(k - 1)                         # the worker a view behind: what was read ahead is kept for view k
    assert steps._frames is not None and steps._frames.have()[1] == read[1]
    shutil.rmtree(partial)                    # the view finished: its folder as recorded
    steps.view(k)
    assert steps._frames is None and steps.prefetch() is None
    assert steps.read_ahead == {k: len(frames) if taken == "all" else 5}
    assert _cache(out, k) == _cache(fresh, k)


def test_nothing_is_read_ahead_before_the_last_view_is_being_taken(reference_session, tmp_path):
    out = _fresh(reference_session, tmp_path / "s")
    steps = StreamingViews(out, ProcessOptions())
    assert steps.prefetch() is None
    steps.views_of(ev.ViewAcquired(0, 4, view_folder(out, 0), 0.0, 1))
    assert steps.prefetch() is None and steps._frames is None


def test_read_view_stack_reads_only_the_frames_it_does_not_have_into_the_stack_it_is_given(reference_session):
    """The frames had (their recorded SHA-256s) are not read: the stack given comes back, its tail read into it;
    the same pixels as reading every frame. A stack of frames not recorded is not used."""
    import numpy as np

    from rangekit.formats.sessions.check import read_view_stack

    session = Session.load(reference_session)
    v = session.views[-1]
    whole = read_view_stack(session, v, v.folder)
    names = [p.name for p in list_images(v.folder)]
    stack = np.zeros_like(whole)
    stack[:5] = whole[:5]
    got = read_view_stack(session, v, v.folder, have=(stack, {name: v.sha256[name] for name in names[:5]}))
    assert got is stack and np.array_equal(got, whole)
    wrong = np.zeros_like(whole)
    got = read_view_stack(session, v, v.folder, have=(wrong, {names[0]: "0" * 64, names[1]: v.sha256[names[1]]}))
    assert got is not wrong and np.array_equal(got, whole) and not wrong.any()
