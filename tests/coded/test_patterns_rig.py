"""Pattern specs and the rig file."""

import json

import numpy as np
import pytest

from rangekit.errors import ConfigError, FileFormatError, PatternError
from rangekit.coded.patterns import PatternSpec, gray_decode, gray_encode, make_pattern_spec
from rangekit.rig.rig_file import Rig, load_rig, save_rig
from rangekit.sim import default_rig


def test_gray_code_neighbours_differ_in_one_bit_and_decode():
    x = np.arange(5000)
    g = gray_encode(x)
    assert np.array_equal(gray_decode(g), x)
    diff = g[1:] ^ g[:-1]
    assert np.all((diff & (diff - 1)) == 0) and np.all(diff > 0)


@pytest.mark.parametrize("size", [(1280, 800), (1024, 768), (37, 5)])
def test_graycode_frames_encode_every_column_and_row(size):
    spec = make_pattern_spec("graycode", size)
    W, H = size
    names = spec.frame_names
    assert names[:2] == ["white", "black"] and spec.n_frames == 2 + 2 * (spec.bits("columns") + spec.bits("rows"))
    if size == (1280, 800):
        assert spec.n_frames == 44
    col_code = np.zeros(W, np.int64)
    row_code = np.zeros(H, np.int64)
    for i, name in enumerate(names[2:], start=2):
        img = spec.frame(i)
        assert img.shape == (H, W) and img.dtype == np.uint8
        if name.endswith("_inv"):
            assert np.array_equal(img, 255 - spec.frame(i - 1))
            continue
        b = int(name.split("_")[1][1:])
        if name.startswith("col"):
            col_code |= (img[0] > 0).astype(np.int64) << b
            assert np.all(img == img[0:1])  # vertical stripes
        else:
            row_code |= (img[:, 0] > 0).astype(np.int64) << b
    assert np.array_equal(gray_decode(col_code), np.arange(W))
    assert np.array_equal(gray_decode(row_code), np.arange(H))


def test_pattern_spec_json_round_trip_and_checks():
    spec = make_pattern_spec("graycode", (1280, 800))
    back = PatternSpec.from_dict(json.loads(json.dumps(spec.to_dict())))
    assert back == spec and back.frame_names == spec.frame_names
    bad = spec.to_dict()
    bad["frames"] = bad["frames"][:-2]
    with pytest.raises(PatternError, match="does not match"):
        PatternSpec.from_dict(bad, where="capture/patterns.json")
    with pytest.raises(PatternError, match="unknown pattern method 'zebra'"):
        make_pattern_spec("zebra", (10, 10))
    with pytest.raises(PatternError, match="frame 44 does not exist"):
        spec.frame(44)


def test_rig_file_round_trip_is_exact(tmp_path):
    rig = default_rig()
    save_rig(rig, tmp_path / "rig.json")
    back = load_rig(tmp_path / "rig.json")
    assert np.array_equal(back.camera.K, rig.camera.K)
    assert np.array_equal(back.projector.T_world_cam, rig.projector.T_world_cam)
    assert np.array_equal(back.projector.dist, rig.projector.dist)
    assert np.array_equal(back.T_world_table, rig.T_world_table)
    assert back.devices == rig.devices
    # The turntable motion is a rotation about the table's z axis.
    M = back.T_world_rotated(np.pi / 2)
    assert np.abs(M[:3, :3] @ [1, 0, 0] - [0, 1, 0]).max() < 1e-15


def test_rig_file_errors_name_file_and_field(tmp_path):
    path = tmp_path / "rig.json"
    data = default_rig().to_dict()
    data["projector"]["K"] = [[1, 0], [0, 1]]
    path.write_text(json.dumps(data))
    with pytest.raises(ConfigError, match=r"rig.json: projector.*'K'"):
        load_rig(path)
    data = default_rig().to_dict()
    del data["cameras"][0]["width"]
    path.write_text(json.dumps(data))
    with pytest.raises(ConfigError, match=r"cameras\[0\].*width"):
        load_rig(path)
    path.write_text("{not json")
    with pytest.raises(FileFormatError, match="rig.json"):
        load_rig(path)
    with pytest.raises(FileFormatError, match="not found"):
        load_rig(tmp_path / "missing.json")
    data = default_rig().to_dict()
    data["schema"] = "other/2"
    path.write_text(json.dumps(data))
    with pytest.raises(ConfigError, match="schema"):
        load_rig(path)
    with pytest.raises(ConfigError, match="at least one camera"):
        Rig(cameras=())
