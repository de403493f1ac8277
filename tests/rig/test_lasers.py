"""Line lasers in the rig file: round trip, the plane's normalisation, errors naming the field."""

from __future__ import annotations

import json

import numpy as np
import pytest

from rangekit.errors import ConfigError
from rangekit.rig.lasers import LineLaser, laser_plane
from rangekit.rig.rig_file import Rig, load_rig, save_rig


def test_a_rig_with_lasers_round_trips(tmp_path, rig):
    plane = laser_plane([1.0, 0.2, 0.0], [0.0, 0.0, 0.05], towards=rig.camera.T_world_cam[:3, 3])
    lasers = (LineLaser(plane=plane * 3.0, name="left", origin=[0.1, -0.4, 0.1], switch=1),
              LineLaser(plane=laser_plane([1.0, -0.2, 0.0], [0, 0, 0]), name="right", channel="green"))
    with_lasers = Rig(cameras=rig.cameras, projector=rig.projector, T_world_table=rig.T_world_table, lasers=lasers)
    save_rig(with_lasers, tmp_path / "rig.json")
    back = load_rig(tmp_path / "rig.json")
    assert [laser.name for laser in back.lasers] == ["left", "right"]
    assert np.allclose(back.lasers[0].plane, plane) and np.isclose(np.linalg.norm(back.lasers[0].normal), 1.0)
    assert back.lasers[0].plane @ np.append(rig.camera.T_world_cam[:3, 3], 1.0) > 0   # normal towards the camera
    assert back.lasers[0].switch == 1 and back.lasers[1].origin is None and back.lasers[1].channel == "green"
    assert "lasers" not in rig.to_dict()   # a rig without lasers writes the file it always wrote


@pytest.mark.parametrize("laser, mention", [
    ({"name": "l"}, "lasers[0]: missing 'plane'"),
    ({"plane": [0, 0, 0, 1]}, "non-zero normal"),
    ({"plane": [1, 0, 0, float("nan")]}, "4 finite numbers"),
    ({"plane": [1, 0, 0]}, "4 finite numbers"),
    ({"plane": [1, 0, 0, 0], "channel": "ultraviolet"}, "channel must be one of red, green, blue, white"),
    ({"plane": [1, 0, 0, 0], "line_width": 0}, "line_width must be a finite number > 0"),
    ({"plane": [1, 0, 0, 0], "fan_angle": 4.0}, "fan_angle must be in (0, pi)"),
    ({"plane": [1, 0, 0, 0], "switch": 0}, "lasers[0].switch"),
    ({"plane": [1, 0, 0, 0], "colour": "red"}, "unknown field(s) 'colour'"),
    ("laser", "lasers[0]: must be an object"),
])
def test_a_bad_laser_names_the_field(tmp_path, rig, laser, mention):
    data = rig.to_dict()
    data["lasers"] = [laser]
    (tmp_path / "rig.json").write_text(json.dumps(data))
    with pytest.raises(ConfigError, match="rig.json") as err:
        load_rig(tmp_path / "rig.json")
    assert mention in str(err.value)
