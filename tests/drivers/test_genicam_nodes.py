"""The GenICam node writes on the real genapi node map of a device that has what the shipped producer's devices
lack (ExposureTime, Gain, the auto features, the trigger nodes).

The node map is genicam's own (``genicam.genapi.NodeMap``) loading a GenICam XML description; only the device's
register memory behind its port is this test's (an ``AbstractPort`` subclass over a bytearray: the boundary where a
GenTL producer would carry the reads and writes to the camera). A register that ignores writes models a camera that
keeps its own value."""

import math
import struct

import pytest

genapi = pytest.importorskip("genicam.genapi")

from rangekit.errors import DeviceError  # noqa: E402
from rangekit.rig.camera_controls import CameraControls  # noqa: E402

#: name -> (kind, address, extra): every node of the described device, each on an 8-byte little-endian register.
NODES = {
    "ExposureAuto": ("enum", 0x00, ("Off", "Continuous")),
    "ExposureTime": ("float", 0x08, (10.0, 1e6)),
    "GainAuto": ("enum", 0x10, ("Off", "Continuous")),
    "Gain": ("float", 0x18, (0.0, 24.0)),
    "BalanceWhiteAuto": ("enum", 0x20, ("Off", "Once", "Continuous")),
    "AcquisitionFrameRateEnable": ("bool", 0x28, None),
    "AcquisitionFrameRate": ("float", 0x30, (1.0, 100.0)),
    "TriggerSelector": ("enum", 0x38, ("FrameStart", "AcquisitionStart")),
    "TriggerMode": ("enum", 0x40, ("Off", "On")),
    "TriggerSource": ("enum", 0x48, ("Software", "Line0", "Line1", "Line2")),
    "TriggerActivation": ("enum", 0x50, ("RisingEdge", "FallingEdge")),
    "TriggerSoftware": ("command", 0x58, None),
}


def _register(name: str, address: int, kind: str) -> str:
    what = "FloatReg" if kind == "float" else "IntReg"
    sign = "" if kind == "float" else "<Sign>Unsigned</Sign>"
    return (f'<{what} Name="{name}Reg"><Address>{address:#x}</Address><Length>8</Length><AccessMode>RW</AccessMode>'
            f'<pPort>Device</pPort><Cachable>WriteThrough</Cachable>{sign}<Endianess>LittleEndian</Endianess>'
            f'</{what}>')


def _node(name: str, kind: str, extra) -> str:
    value = f"<pValue>{name}Reg</pValue>"
    if kind == "enum":
        entries = "".join(f'<EnumEntry Name="{v}"><Value>{i}</Value></EnumEntry>' for i, v in enumerate(extra))
        return f'<Enumeration Name="{name}">{entries}{value}</Enumeration>'
    if kind == "float":
        return f'<Float Name="{name}">{value}<Min>{extra[0]}</Min><Max>{extra[1]}</Max></Float>'
    if kind == "bool":
        return f'<Boolean Name="{name}">{value}<OnValue>1</OnValue><OffValue>0</OffValue></Boolean>'
    return f'<Command Name="{name}">{value}<CommandValue>1</CommandValue></Command>'


def _xml(names) -> str:
    body = "".join(_node(n, NODES[n][0], NODES[n][2]) + _register(n, NODES[n][1], NODES[n][0]) for n in names)
    features = "".join(f"<pFeature>{n}</pFeature>" for n in names)
    return ('<?xml version="1.0" encoding="utf-8"?><RegisterDescription ModelName="Registers" VendorName="rangekit" '
            'ToolTip="test device" StandardNameSpace="None" SchemaMajorVersion="1" SchemaMinorVersion="1" '
            'SchemaSubMinorVersion="0" MajorVersion="1" MinorVersion="0" SubMinorVersion="0" '
            'ProductGuid="11111111-2222-3333-4444-555555555555" VersionGuid="11111111-2222-3333-4444-666666666666" '
            'xmlns="http://www.genicam.org/GenApi/Version_1_1">'
            f'<Category Name="Root">{features}</Category>{body}<Port Name="Device"/></RegisterDescription>')


class Registers(genapi.AbstractPort):
    """The device's register memory; writes to ``ignored`` addresses are dropped (the camera keeps its value)."""

    def __init__(self):
        super().__init__()
        self.memory, self.ignored = bytearray(0x60), set()

    def is_open(self):
        return True

    def get_access_mode(self):
        return genapi.EAccessMode.RW

    def read(self, address, length):
        return bytes(self.memory[address:address + length])

    def write(self, address, value):
        if address not in self.ignored:
            self.memory[address:address + len(value)] = value

    def float(self, name):
        return struct.unpack_from("<d", self.memory, NODES[name][1])[0]

    def int(self, name):
        return struct.unpack_from("<Q", self.memory, NODES[name][1])[0]


def _device(names=tuple(NODES)):
    nm, port = genapi.NodeMap(), Registers()
    nm.load_xml_from_string(_xml(names))
    nm.connect(port, "Device")
    return nm, port


def test_controls_written_auto_off_and_read_back():
    from rangekit.drivers.genicam.nodes import apply_controls

    nm, dev = _device()
    dev.memory[0x00] = dev.memory[0x10] = 1         # the camera starts with auto exposure and auto gain
    limits = apply_controls(nm, CameraControls(exposure_us=16_667.0, iso=200, fps=30.0), device="cam")
    assert limits == []
    assert dev.int("ExposureAuto") == 0 and dev.int("GainAuto") == 0 and dev.int("BalanceWhiteAuto") == 0
    assert dev.float("ExposureTime") == 16_667.0 and dev.float("AcquisitionFrameRate") == 30.0
    assert dev.float("Gain") == pytest.approx(20 * math.log10(2)) and dev.int("AcquisitionFrameRateEnable") == 1
    apply_controls(nm, CameraControls(exposure_us=None, iso=None, white_balance_k=None), device="cam")
    assert (dev.int("ExposureAuto"), dev.int("GainAuto"), dev.int("BalanceWhiteAuto")) == (1, 1, 2)


def test_a_camera_that_keeps_its_own_value_or_refuses_one_is_one_line():
    from rangekit.drivers.genicam.nodes import apply_controls

    nm, dev = _device()
    dev.ignored.add(NODES["ExposureTime"][1])
    with pytest.raises(DeviceError, match=r"^cam: node ExposureTime: wrote 33333.0, read back 0.0; the camera did not "
                                          r"take it \(the device takes 10..1e\+06\)$"):
        apply_controls(nm, CameraControls(), device="cam")
    nm, dev = _device()
    with pytest.raises(DeviceError, match=r"^cam: node Gain refused 30.1\d* \(Value .* must be smaller than or equal "
                                          r"24.0+\.\); the device takes 0..24$"):
        apply_controls(nm, CameraControls(iso=3200), device="cam")


def test_what_the_device_lacks_is_a_limit():
    from rangekit.drivers.genicam.nodes import apply_controls, apply_trigger

    nm, _ = _device(("ExposureAuto", "ExposureTime", "AcquisitionFrameRate"))
    assert apply_controls(nm, CameraControls(), device="cam") == [
        "no Gain node: capture.camera.iso 100 is not applied, the device's gain is kept"]
    assert apply_controls(nm, CameraControls(white_balance_k=None), device="cam")[-1] == \
        "no BalanceWhiteAuto node: the device has no automatic white balance; capture.camera asks for it"
    triggered, limits = apply_trigger(nm, "Line1", "RisingEdge", device="cam")
    assert not triggered and limits[0].startswith("no TriggerMode node: devices.camera.trigger_source Line1 is not "
                                                  "applied, the device runs free")


def test_triggers():
    from rangekit.drivers.genicam.nodes import apply_trigger

    nm, dev = _device()
    assert apply_trigger(nm, "Line1", "FallingEdge", device="cam") == (True, [])
    assert (dev.int("TriggerSelector"), dev.int("TriggerMode"), dev.int("TriggerSource"),
            dev.int("TriggerActivation")) == (0, 1, 2, 1)
    assert apply_trigger(nm, "Software", "RisingEdge", device="cam") == (True, [])
    assert dev.int("TriggerSource") == 0 and dev.int("TriggerActivation") == 1    # a software trigger has no edge
    nm.TriggerSoftware.execute()
    assert dev.int("TriggerSoftware") == 1
    assert apply_trigger(nm, None, "RisingEdge", device="cam") == (False, [])
    assert dev.int("TriggerMode") == 0
    with pytest.raises(DeviceError, match="^cam: node TriggerSource has no value 'Line7'; the device takes Software, "
                                          "Line0, Line1, Line2$"):
        apply_trigger(nm, "Line7", "RisingEdge", device="cam")
