"""The rig file as a user writes it: the template, the checks of every field, and its documentation."""

import copy
import json
import re
from pathlib import Path

import numpy as np
import pytest

from rangekit.drivers import open_rig_devices
from rangekit.rig.checks import (CAPTURE_FIELDS, DEVICE_FIELDS, validate_capture, validate_devices,
                                 validate_rig_for_hardware)
from rangekit.errors import ConfigError
from rangekit.rig.rig_file import CAMERA_FIELDS, RIG_FIELDS, Rig, load_rig, save_rig, template_rig
from rangekit.sim import default_rig

DOC = Path(__file__).resolve().parents[2] / "docs" / "rig.md"


def test_template_is_plain_json_and_round_trips(tmp_path):
    t = template_rig()
    assert json.loads(json.dumps(t)) == t
    path = tmp_path / "rig.json"
    path.write_text(json.dumps(t, indent=2))
    rig = load_rig(path)
    assert rig.to_dict() == t
    save_rig(rig, tmp_path / "again.json")
    assert json.loads((tmp_path / "again.json").read_text()) == t
    assert template_rig() is not t and template_rig() == t  # a fresh dict each call


def test_template_geometry_is_consistent():
    rig = Rig.from_dict(template_rig())
    cam, proj = rig.camera, rig.projector
    assert cam.size == (1280, 800) and proj.size == (1280, 800)
    np.testing.assert_array_equal(cam.T_world_cam, np.eye(4))
    # The projector is 0.2 m to the camera's right and looks at the point 0.5 m ahead of the camera.
    np.testing.assert_allclose(proj.center, [0.2, 0.0, 0.0])
    np.testing.assert_allclose(proj.project(np.array([[0.0, 0.0, 0.5]])), [[639.5, 399.5]], atol=1e-6)
    # The table is 0.5 m ahead, below the optical axis (y down), its axis pointing up (world -y),
    # and both devices see its centre.
    T = rig.T_world_table
    np.testing.assert_allclose(T[:3, 3], [0.0, 0.05, 0.5])
    np.testing.assert_allclose(T[:3, 2], [0.0, -1.0, 0.0])
    for dev in (cam, proj):
        u, v = dev.project(T[None, :3, 3])[0]
        assert 0 <= u < dev.width and 0 <= v < dev.height
    # A positive angle turns counter-clockwise seen from above: table x -> table y.
    M = rig.T_world_rotated(np.pi / 2)
    np.testing.assert_allclose(M[:3, :3] @ T[:3, 0], T[:3, 1], atol=1e-15)


def test_template_and_simulator_rigs_pass_the_hardware_checks():
    validate_rig_for_hardware(Rig.from_dict(template_rig()), where="rig.json")
    validate_rig_for_hardware(default_rig(), where="sim rig")
    validate_devices({}, where="rig.json")
    validate_capture({}, where="rig.json")
    # calibration_to_rig records where the calibration came from in devices.depthai.
    validate_devices({"depthai": {"device_id": "X", "sockets": ["CAM_A", "CAM_B"], "size": [640, 400]}},
                     where="rig.json")
    ok = {"turntable": {"protocol": "FabScan", "port": "socket://localhost:7777", "baud": None},
          "projector": {"control": {"protocol": "pjlink", "port": "10.0.0.5:4352", "password": "x", "timeout": 1}},
          "camera": {"type": "sim"}}
    validate_devices(ok, where="rig.json")


def _devices_with(path: str, value):
    """The template's devices with the field at dotted ``path`` set to ``value`` (``...`` deletes it)."""
    devices = copy.deepcopy(template_rig()["devices"])
    *parents, leaf = path.split(".")[1:]
    node = devices
    for key in parents:
        node = node[key]
    if value is ...:
        del node[leaf]
    else:
        node[leaf] = value
    return devices


BAD_DEVICES = [
    ("devices.turntable.baud", "115k", "positive integer"),
    ("devices.turntable.baud", 0, "positive integer"),
    ("devices.turntable.baud", True, "positive integer"),
    ("devices.turntable.protocol", "zaxis", "unknown turntable protocol 'zaxis'; known: 'fabscan', 'horus'"),
    ("devices.turntable.protocol", ..., "missing"),
    ("devices.turntable.port", "", "non-empty string"),
    ("devices.turntable.port", 0, "non-empty string"),
    ("devices.turntable.port", ..., "missing"),
    ("devices.turntable.type", "serial", "'sim' or absent"),
    ("devices.turntable.speed", 3, "unknown field"),
    ("devices.turntable", [1], "must be an object"),
    ("devices.projector.display", -1, "non-negative integer"),
    ("devices.projector.display", "HDMI-1", "non-negative integer"),
    ("devices.projector.control", "escvp21", "must be an object"),
    ("devices.projector.control.protocol", "benq2", "unknown projector control protocol 'benq2'"),
    ("devices.projector.control.port", None, "non-empty string"),
    ("devices.projector.control.baud", -9600, "positive integer"),
    ("devices.projector.control.timeout", 0, "positive number of seconds"),
    ("devices.projector.control.password", "secret", "only the 'pjlink' protocol"),
    ("devices.projector.control.pasword", "secret", "unknown field"),
    ("devices.camera.type", "kinect", "one of 'sim', 'depthai'"),
    ("devices.camera.type", ..., "one of 'sim', 'depthai'"),
    ("devices.camera.socket", "RGB", "CAM_A"),
    ("devices.camera.id", 1234, "string"),
    ("devices.scanner", {}, "unknown field"),
]


@pytest.mark.parametrize("path, value, expected", BAD_DEVICES,
                         ids=[f"{p}={v!r}" for p, v, _ in BAD_DEVICES])
def test_bad_device_fields_are_named(path, value, expected):
    with pytest.raises(ConfigError) as info:
        validate_devices(_devices_with(path, value), where="my/rig.json")
    msg = str(info.value)
    assert msg.startswith(f"my/rig.json: {path}"), msg
    assert expected in msg


def test_pjlink_port_and_depthai_record_are_checked():
    bad = {"projector": {"control": {"protocol": "pjlink", "port": "10.0.0.5:http"}}}
    with pytest.raises(ConfigError, match=r"^rig.json: devices.projector.control.port: .*host:port"):
        validate_devices(bad, where="rig.json")
    with pytest.raises(ConfigError, match=r"^rig.json: devices.depthai.size: "):
        validate_devices({"depthai": {"size": [640]}}, where="rig.json")
    with pytest.raises(ConfigError, match=r"^rig.json: devices.depthai.sockets: "):
        validate_devices({"depthai": {"sockets": ["RGB"]}}, where="rig.json")
    with pytest.raises(ConfigError, match=r"^rig.json: devices: must be an object"):
        validate_devices([], where="rig.json")


BAD_CAPTURE = [
    ("pattern_delay_s", "0.1s", "number of seconds"),
    ("pattern_delay_s", -0.1, "from 0 to 10"),
    ("pattern_delay_s", 100, "seconds, not milliseconds"),
    ("pattern_delay_s", float("nan"), "number of seconds"),
    ("turntable_settle_s", None, "number of seconds"),
    ("turntable_settle_s", 500, "from 0 to 60"),
    ("bits", 11, "8, 10, 12 or 16"),
    ("trigger", "vsync", "must be 'none' or 'projector'"),
    ("trigger", True, "must be 'none' or 'projector'"),
    ("exposure", 10, "unknown field; capture has only camera, trigger, pattern_delay_s, turntable_settle_s, bits"),
]


@pytest.mark.parametrize("key, value, expected", BAD_CAPTURE, ids=[f"{k}={v!r}" for k, v, _ in BAD_CAPTURE])
def test_bad_capture_fields_are_named(key, value, expected):
    capture = dict(template_rig()["capture"], **{key: value})
    with pytest.raises(ConfigError) as info:
        validate_capture(capture, where="my/rig.json")
    msg = str(info.value)
    assert msg.startswith(f"my/rig.json: capture.{key}: ") and expected in msg, msg


def test_hardware_check_needs_a_projector_for_a_display():
    data = template_rig()
    data["projector"] = None
    with pytest.raises(ConfigError, match=r"^rig.json: devices.projector.display: .*'projector' is null"):
        validate_rig_for_hardware(Rig.from_dict(data), where="rig.json")


def test_open_rig_devices_checks_everything_before_opening_anything(tmp_path):
    # The turntable port does not exist: had anything been opened, the error would be about the port.
    data = template_rig()
    data["devices"]["turntable"]["port"] = str(tmp_path / "no-such-port")
    data["capture"]["pattern_delay_s"] = "fast"
    with pytest.raises(ConfigError, match=r"^rig.json: capture.pattern_delay_s: "):
        open_rig_devices(Rig.from_dict(data), where="rig.json")
    data["capture"]["pattern_delay_s"] = 0.1
    data["devices"]["camera"]["socket"] = "CAM_Z"
    with pytest.raises(ConfigError, match=r"^rig.json: devices.camera.socket: "):
        open_rig_devices(Rig.from_dict(data), where="rig.json")


def _rig_with(path: str, value):
    """The template with the field at ``path`` (e.g. ``cameras[0].dist``) set to ``value`` (``...`` deletes)."""
    data = template_rig()
    keys = [int(k) if k.isdigit() else k for k in re.findall(r"[^.\[\]]+", path)]
    node = data
    for key in keys[:-1]:
        node = node[key]
    if value is ...:
        del node[keys[-1]]
    else:
        node[keys[-1]] = value
    return data


BAD_RIGS = [
    ("cameras[0].K", [[1000.0, 0.0], [0.0, 1000.0]], "found shape (2, 2)"),
    ("cameras[0].K", [[1000.0, 1.0, 639.5], [0.0, 1000.0, 399.5], [0.0, 0.0, 1.0]], "zero skew"),
    ("cameras[0].K", [[-1000.0, 0.0, 639.5], [0.0, 1000.0, 399.5], [0.0, 0.0, 1.0]], "fx, fy > 0"),
    ("cameras[0].K", "eye", "3x3 array of finite numbers, found 'eye'"),
    ("projector.K", [[1500.0, 0.0, 639.5], [0.0, 1500.0, float("nan")], [0.0, 0.0, 1.0]], "non-finite"),
    ("cameras[0].width", -1280, "positive integer"),
    ("cameras[0].width", 1280.5, "positive integer"),
    ("projector.height", "800", "positive integer"),
    ("cameras[0].dist", [0.1, 0.2, 0.3], "found 3 value(s)"),
    ("projector.dist", [[0.1, 0.2, 0.0, 0.0]], "0, 4, 5, 8, 12 or 14"),
    ("cameras[0].dist", [0.0] * 12 + [0.01, 0.0], "tilted-sensor"),
    ("cameras[0].T_world_cam", np.diag([2.0, 1.0, 1.0, 1.0]).tolist(), "rigid"),
    ("projector.T_world_cam", np.diag([1.0, 1.0, -1.0, 1.0]).tolist(), "det +1"),
    ("cameras[0].T_world_cam", np.eye(3).tolist(), "found shape (3, 3)"),
    ("cameras[0].name", 7, "must be a string"),
    ("T_world_table", np.eye(3).tolist(), "found shape (3, 3)"),
    ("T_world_table", (np.eye(4) * 2).tolist(), "rigid"),
    ("schema", "rangekit.rig/2", "must be 'rangekit.rig/1'"),
    ("cameras", [], "non-empty list"),
    ("devices", [], "must be an object"),
    ("capture", "fast", "must be an object"),
]


@pytest.mark.parametrize("path, value, expected", BAD_RIGS, ids=[f"{p}-{i}" for i, (p, _, _) in enumerate(BAD_RIGS)])
def test_load_rig_names_file_and_field(tmp_path, path, value, expected):
    file = tmp_path / "rig.json"
    file.write_text(json.dumps(_rig_with(path, value)))
    with pytest.raises(ConfigError) as info:
        load_rig(file)
    msg = str(info.value)
    assert msg.startswith(f"{file}: {path}: ") and expected in msg, msg


def test_load_rig_rejects_unknown_and_missing_fields(tmp_path):
    file = tmp_path / "rig.json"
    file.write_text(json.dumps(dict(template_rig(), turntable={"axis": [0, 0, 1]})))
    with pytest.raises(ConfigError, match=r"rig.json: unknown top-level field\(s\) 'turntable'; a rig file has only "
                                          r"schema, cameras, projector, T_world_table, devices, capture"):
        load_rig(file)
    file.write_text(json.dumps(_rig_with("cameras[0].distortion", [0.1, 0.0, 0.0, 0.0])))
    with pytest.raises(ConfigError, match=r"rig.json: cameras\[0\]: unknown field\(s\) 'distortion'"):
        load_rig(file)
    file.write_text(json.dumps(_rig_with("projector.K", ...)))
    with pytest.raises(ConfigError, match=r"rig.json: projector: missing field\(s\) 'K'"):
        load_rig(file)
    file.write_text(json.dumps(_rig_with("cameras[0]", 3)))
    with pytest.raises(ConfigError, match=r"rig.json: cameras\[0\]: must be an object"):
        load_rig(file)
    # Optional fields: no distortion, identity pose, no projector, no turntable, no devices.
    data = template_rig()
    for key in ("dist", "T_world_cam", "name"):
        del data["cameras"][0][key]
    data.update(projector=None, T_world_table=None)
    del data["devices"], data["capture"]
    file.write_text(json.dumps(data))
    rig = load_rig(file)
    assert rig.camera.dist.size == 0 and rig.projector is None and rig.T_world_table is None
    np.testing.assert_array_equal(rig.camera.T_world_cam, np.eye(4))


def _paths(value, prefix: str = ""):
    """Every dotted field path of a JSON dict; list items as ``[]``."""
    if isinstance(value, dict):
        for key, sub in value.items():
            path = f"{prefix}.{key}" if prefix else key
            yield path
            yield from _paths(sub, path)
    elif isinstance(value, list) and value and isinstance(value[0], dict):
        for item in value:
            yield from _paths(item, f"{prefix}[]")


def test_docs_describe_every_field():
    doc = DOC.read_text()
    documented = set(re.findall(r"`([A-Za-z_][\w.\[\]]*)`", doc))
    paths = set(_paths(template_rig()))
    assert {"cameras[].K", "projector.dist", "devices.camera.socket", "capture.pattern_delay_s"} <= paths
    paths |= set(RIG_FIELDS)
    paths |= {f"{owner}.{f}" for owner in ("cameras[]", "projector") for f in CAMERA_FIELDS}
    paths |= {f"{owner}.{f}" for owner, fields in DEVICE_FIELDS.items() for f in fields}
    paths |= {f"capture.{f}" for f in CAPTURE_FIELDS}
    missing = sorted(p for p in paths if p not in documented)
    assert not missing, f"docs/rig.md does not document {missing}"
    # The template printed in the docs is the one the code makes.
    block = re.search(r"```json\n(.*?)```", doc, re.S).group(1)
    assert json.loads(block) == template_rig()


def test_every_camera_type_a_rig_file_may_name_has_its_driver():
    """The camera drivers are a registry (rangekit.drivers.CAMERA_DRIVERS); the rig file's check accepts its
    names and the simulator's, nothing else."""
    from rangekit.drivers import CAMERA_DRIVERS
    from rangekit.rig.checks import CAMERA_TYPES

    from rangekit.rig.checks import CAMERA_SECTION_FIELDS, CAMERA_TEMPLATES, validate_devices

    assert set(CAMERA_TYPES) == {"sim", *CAMERA_DRIVERS} == {"sim", *CAMERA_SECTION_FIELDS} == {"sim", *CAMERA_TEMPLATES}
    for kind in CAMERA_DRIVERS:    # rig init --camera KIND writes a section its check takes
        assert template_rig(camera=kind)["devices"]["camera"]["type"] == kind
        validate_devices({"camera": CAMERA_TEMPLATES[kind]}, where="t")
        with pytest.raises(ConfigError, match=rf"t: devices.camera.colour: unknown field; a '{kind}' camera has only"):
            validate_devices({"camera": {**CAMERA_TEMPLATES[kind], "colour": 1}}, where="t")


def test_a_camera_drivers_missing_package_is_one_line_naming_its_extra(monkeypatch):
    from rangekit.drivers.cameras import CAMERA_DRIVERS, CameraDriver, MissingPackage, camera_driver

    monkeypatch.setitem(CAMERA_DRIVERS, "nothing", CameraDriver("rangekit.drivers.cameras", "a camera",
                                                                 ("rangekit_no_such_package",), "nothing"))
    with pytest.raises(MissingPackage, match=r"nothing cameras \(a camera\) need the Python package "
                                             r"'rangekit_no_such_package'.*pip install 'rangekit\[nothing\]'"):
        camera_driver("nothing")
    module = camera_driver("depthai")
    assert callable(module.open_camera) and callable(module.list_cameras)


def test_the_mesh_formats_are_listed_once():
    """--format's choices are the mesh writers of rangekit.formats.meshes, the one list of them."""
    from rangekit.app.process.fused_outputs import MESH_EXPORT_FORMATS
    from rangekit.formats.meshes import MESH_FORMATS

    assert [f".{fmt}" for fmt in MESH_EXPORT_FORMATS] == list(MESH_FORMATS)
