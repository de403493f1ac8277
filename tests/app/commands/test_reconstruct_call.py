"""``rk.reconstruct``: one capture to a cloud (a folder, files or arrays; the rig and the pattern from the folder or
given), checked against the simulator's truth (the door's argument checks: tests/test_front_door.py)."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

import rangekit as rk
from rangekit.coded.patterns import make_pattern_spec
from rangekit.errors import ConfigError
from rangekit.sim import SimRig, default_scene
from rangekit.sim.writers.capture import write_capture


@pytest.fixture(scope="module")
def capture(tmp_path_factory, small_rig):
    """A Gray-code + phase-shift capture of the lumpy object on the small rig, written as a capture folder,
    with the true surface points the camera sees."""
    sim = SimRig(default_scene("lumpy"), small_rig, seed=3)
    spec = make_pattern_spec("hybrid", (small_rig.projector.width, small_rig.projector.height))
    folder = tmp_path_factory.mktemp("front_door") / "capture"
    paths = write_capture(sim, spec, folder)
    truth = sim.ground_truth()
    seen = truth.xyz[np.isfinite(truth.xyz[..., 0])]
    return folder, paths, spec, seen


def test_a_capture_folder_becomes_a_cloud_on_the_true_surface(capture):
    folder, _, _, seen = capture
    cloud = rk.reconstruct(folder)               # the rig and the patterns from the folder
    assert isinstance(cloud, rk.PointCloud) and len(cloud) > 10_000
    d, _ = cKDTree(seen).query(cloud.points)
    assert np.median(d) < 0.2e-3 and np.percentile(d, 95) < 1.0e-3   # metres: the truth's own pixels


def test_files_or_arrays_with_the_rig_and_a_pattern_name_give_the_same_cloud(capture, small_rig, tmp_path):
    from rangekit.io import read_png

    folder, paths, spec, _ = capture
    by_folder = rk.reconstruct(folder)
    rk.save_rig(small_rig, tmp_path / "rig.json")
    by_files = rk.reconstruct(paths, tmp_path / "rig.json", pattern="hybrid")
    by_arrays = rk.reconstruct([read_png(p) for p in paths], rk.load_rig(tmp_path / "rig.json"), pattern=spec)
    for cloud in (by_files, by_arrays):
        assert np.array_equal(cloud.points, by_folder.points)


def test_what_is_missing_is_named(capture, small_rig):
    folder, paths, _, _ = capture
    with pytest.raises(ConfigError, match="no rig with a projector; give rig="):
        rk.reconstruct(paths, pattern="hybrid")
    with pytest.raises(ConfigError, match="no pattern set; give pattern="):
        rk.reconstruct(paths, small_rig)
