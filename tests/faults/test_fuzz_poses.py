"""Property: the poses-file reader returns valid rigid transforms or raises a RangekitError, never anything
else, for any JSON a user or a crash can leave in poses.json."""

from __future__ import annotations

import json

import numpy as np
from hypothesis import HealthCheck, given, settings, strategies as st

from rangekit.errors import RangekitError
from rangekit.formats.poses import load_poses

JSON = st.recursive(st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
                    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=8), inner, max_size=5),
                    max_leaves=30)
MATRIX = st.lists(st.lists(st.floats() | st.integers(-10, 10), min_size=0, max_size=5), min_size=0, max_size=5)
VIEW = st.fixed_dictionaries({}, optional={"source": JSON, "T_world_view": MATRIX | JSON})
POSES = st.fixed_dictionaries({}, optional={"schema": JSON, "world": JSON, "views": st.lists(VIEW | JSON, max_size=4)})


def _check(tmp_path, data) -> None:
    path = tmp_path / "poses.json"
    path.write_text(json.dumps(data, allow_nan=True))
    try:
        sources, T = load_poses(path)
    except RangekitError as exc:
        assert str(path) in str(exc)
        return
    assert len(sources) == len(T) and T.shape[1:] == (4, 4)
    assert np.all(np.isfinite(T))
    assert np.allclose(T[:, 3], [0, 0, 0, 1])
    assert np.allclose(np.linalg.det(T[:, :3, :3]), 1.0, atol=1e-6)


@settings(max_examples=150, deadline=None, database=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(data=POSES | JSON)
def test_any_poses_file_gives_poses_or_a_rangekit_error(tmp_path, data):
    _check(tmp_path, data)


@settings(max_examples=100, deadline=None, database=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(T=st.lists(st.lists(st.floats(allow_nan=True, allow_infinity=True), min_size=4, max_size=4),
                  min_size=4, max_size=4))
def test_any_4x4_matrix_is_a_rigid_transform_or_refused(tmp_path, T):
    _check(tmp_path, {"views": [{"source": "a.ply", "T_world_view": T}]})


def test_a_reflection_or_a_nan_translation_is_refused(tmp_path):
    import pytest

    for T in (np.diag([1.0, 1.0, -1.0, 1.0]), np.array([[1, 0, 0, np.nan], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]),
              np.array([[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1.0]])):
        (tmp_path / "p.json").write_text(json.dumps({"views": [{"source": "a", "T_world_view": T.tolist()}]}))
        with pytest.raises(RangekitError, match="rigid transform"):
            load_poses(tmp_path / "p.json")
