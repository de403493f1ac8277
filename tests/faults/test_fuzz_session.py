"""Property-based tests of the session manifest reader: whatever ``session.json`` holds (any
JSON value, a valid manifest with a key dropped, a value replaced by junk, nan, huge integers, nested
junk, bytes that are not JSON), ``Session.load`` gives a valid Session or a RangekitError, never
anything else."""

from __future__ import annotations

import json
import math
import tempfile
from dataclasses import asdict
from pathlib import Path

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from rangekit.coded.patterns import make_pattern_spec
from rangekit.errors import RangekitError
from rangekit.formats.sessions.session import ScanPlan, Session, SimulatorSettings
from rangekit.rig.rig_file import save_rig
from rangekit.sim import ImagingModel, default_rig

FUZZ = settings(deadline=None, max_examples=150, suppress_health_check=[HealthCheck.too_slow])

_scalars = st.one_of(st.none(), st.booleans(), st.integers(), st.integers(min_value=-2**70, max_value=2**70),
                     st.just(10**400), st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=12),
                     st.sampled_from(["done", "pending", "view_000", "../../etc/passwd", "/etc/passwd", "lumpy",
                                      "object/x.ply", "graycode", "rangekit.session/1", "0" * 64]))
json_values = st.recursive(_scalars, lambda inner: st.one_of(st.lists(inner, max_size=4),
                                                             st.dictionaries(st.text(max_size=8), inner, max_size=4)),
                           max_leaves=12)


@pytest.fixture(scope="module")
def folder():
    """A session folder whose manifest the tests overwrite: 3 views (two done, with checksums), rig.json."""
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        rig = default_rig()
        save_rig(rig, d / "rig.json")
        spec = make_pattern_spec("white", (rig.projector.width, rig.projector.height))
        session = Session.new(d, ScanPlan(3), spec, rig,
                              simulator=SimulatorSettings("lumpy", 7, asdict(ImagingModel())))
        digests = {f"{j:03d}.png": f"{j:064x}" for j in range(spec.n_frames)}
        session = session.with_view_done(0, digests).with_view_done(1, digests)
        session.save()
        assert Session.load(d).views[1].sha256 == digests   # the fuzzing starts from a valid manifest
        yield d, session.to_dict()


def _load(folder: Path, text: str):
    (folder / "session.json").write_text(text)
    try:
        session = Session.load(folder)
    except RangekitError as exc:
        assert str(exc) and "session" in str(exc)
        return None
    # A valid session: its fields are what the rest of rangekit relies on.
    assert len(session.views) == session.plan.n_views >= 1
    assert all(v.index == k and math.isfinite(v.angle) for k, v in enumerate(session.views))
    assert session.simulator is None or 0 <= session.simulator.seed < 2**32
    return session


@FUZZ
@given(value=json_values)
def test_any_json_value(folder, value):
    _load(folder[0], json.dumps(value))


def _paths(value, prefix=()):
    """Every (key path) inside a JSON value."""
    yield prefix
    if isinstance(value, dict):
        for k, v in value.items():
            yield from _paths(v, prefix + (k,))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            yield from _paths(v, prefix + (i,))


def _parent(data, path):
    for k in path[:-1]:
        data = data[k]
    return data


@FUZZ
@given(data=st.data())
def test_a_mutated_valid_manifest(folder, data):
    d, manifest = folder
    manifest = json.loads(json.dumps(manifest))
    for _ in range(data.draw(st.integers(1, 3))):
        paths = [p for p in _paths(manifest) if p]
        path = data.draw(st.sampled_from(paths))
        parent = _parent(manifest, path)
        action = data.draw(st.sampled_from(["drop", "replace", "add"]))
        if action == "drop":
            del parent[path[-1]]
        elif action == "replace":
            parent[path[-1]] = data.draw(json_values)
        elif isinstance(parent, dict):
            parent[data.draw(st.text(max_size=8))] = data.draw(json_values)
        else:
            parent.append(data.draw(json_values))
        if not any(True for _ in _paths(manifest)):
            break
    _load(d, json.dumps(manifest))


@FUZZ
@given(text=st.one_of(st.text(max_size=64), st.binary(max_size=64).map(lambda b: b.decode("latin-1"))))
def test_text_that_may_not_be_json(folder, text):
    _load(folder[0], text)


def test_the_manifest_round_trips(folder):
    d, manifest = folder
    session = _load(d, json.dumps(manifest))
    assert session is not None and session.to_dict() == manifest
