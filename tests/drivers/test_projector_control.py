"""Projector control drivers against simulated ESC/VP21 (pty) and PJLink (loopback TCP) peers."""

import time

import pytest

from rangekit.drivers.projector_control import EscVp21Projector, PJLinkProjector, make_projector_control
from rangekit.errors import CommandError, ConfigError, DeviceDisconnected, DeviceTimeout
from rangekit.sim.devices.projector_firmware import SimEscVp21, SimPJLink


@pytest.fixture
def escvp21():
    fw = SimEscVp21()
    yield fw
    fw.stop()


def test_escvp21_power_blank_source(escvp21):
    p = make_projector_control("escvp21", escvp21.port, timeout=1.0)
    assert not p.is_on()
    with pytest.raises(CommandError, match="MUTE ON.*refused"):
        p.blank(True)  # refused while off; the next command still works
    p.power(True)
    assert p.is_on() and escvp21.power
    p.blank(True)
    assert escvp21.mute
    p.source("A0")
    assert escvp21.source == "A0"
    p.close()


@pytest.mark.parametrize("password", [None, "secret"])
def test_pjlink_power_blank_input(password):
    srv = SimPJLink(password=password)
    try:
        p = make_projector_control("pjlink", f"127.0.0.1:{srv.port}", password=password, timeout=1.0)
        with pytest.raises(CommandError, match="ERR3"):
            p.blank(True)
        p.power(True)
        assert p.is_on()
        p.blank(True)
        p.source("32")
        assert (srv.avmt, srv.input) == ("31", "32")
        p.close()
        if password:
            bad = PJLinkProjector("127.0.0.1", srv.port, password="wrong", timeout=1.0)
            with pytest.raises(CommandError, match="authentication"):
                bad.is_on()
            bad.close()
    finally:
        srv.stop()


def test_a_projector_that_never_answers_times_out():
    fw = SimEscVp21(silent=True)
    t = time.monotonic()
    with pytest.raises(DeviceTimeout, match=r"projector at .*: no ':' prompt within 0.5 s"):
        EscVp21Projector(fw.port, timeout=0.5)
    assert time.monotonic() - t < 1.5
    fw.stop()
    srv = SimPJLink(silent=True)
    t = time.monotonic()
    with pytest.raises(DeviceTimeout, match="PJLink greeting"):
        PJLinkProjector("127.0.0.1", srv.port, timeout=0.5)
    assert time.monotonic() - t < 1.5
    srv.stop()


def test_bad_configuration():
    with pytest.raises(ConfigError, match="unknown projector protocol 'benq2'; known: escvp21, pjlink"):
        make_projector_control("benq2", "/dev/ttyUSB9")
    with pytest.raises(DeviceDisconnected, match="ttyUSB97"):
        make_projector_control("escvp21", "/dev/ttyUSB97")
    srv = SimPJLink(password="x")
    with pytest.raises(ConfigError, match="password"):
        PJLinkProjector("127.0.0.1", srv.port, timeout=0.5)
    srv.stop()


def test_rig_file_devices_open_and_fail_clearly():
    from rangekit.drivers import open_rig_devices
    from rangekit.rig.rig_file import Rig
    from rangekit.sim import default_rig
    from rangekit.sim.devices.firmware import start_firmware

    base = default_rig()
    fw = start_firmware("horus")
    pj = SimEscVp21()
    try:
        rig = Rig(cameras=base.cameras, projector=base.projector, T_world_table=base.T_world_table,
                  devices={"turntable": {"protocol": "horus", "port": fw.port},
                           "projector": {"control": {"protocol": "escvp21", "port": pj.port}},
                           "camera": {"type": "sim"}})
        hw = open_rig_devices(rig, open_display=False)
        hw.turntable.rotate_to(0.5)
        hw.projector_control.power(True)
        assert pj.power and abs(fw.position_deg - 28.6479) < 0.12
        hw.close()
        bad = Rig(cameras=base.cameras, devices={"turntable": {"protocol": "zaxis", "port": fw.port}})
        with pytest.raises(ConfigError, match=r"rig.json: devices.turntable.protocol: .*'zaxis'"):
            open_rig_devices(bad, where="rig.json")
        missing = Rig(cameras=base.cameras, devices={"turntable": {"protocol": "horus", "port": "/dev/ttyUSB98"}})
        t = time.monotonic()
        with pytest.raises(DeviceDisconnected, match="ttyUSB98"):
            open_rig_devices(missing)
        assert time.monotonic() - t < 2
        fw.inject("garbage")  # a wrong baud rate looks like garbage
        from rangekit.errors import ProtocolError

        with pytest.raises(ProtocolError, match="baud"):
            open_rig_devices(Rig(cameras=base.cameras, devices={"turntable": {"protocol": "horus", "port": fw.port}}))
    finally:
        fw.stop()
        pj.stop()
