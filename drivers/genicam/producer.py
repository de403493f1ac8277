"""The GenTL producer of a GenICam camera, and the device chosen on it.

A camera maker ships a *GenTL producer*: a shared library (``.cti``) exporting the GenTL C functions
(``GCInitLib``, ``TLOpen``, ``IFOpenDevice``, ...). harvesters loads it and opens its devices. Where it comes from:

1. ``devices.camera.producer`` (the rig file): the path of a ``.cti`` file;
2. else the environment variable ``GENICAM_GENTL64_PATH`` (the GenTL standard's): folders or ``.cti`` files
   separated by ``os.pathsep``, every ``.cti`` in them.

A path that is not a GenTL library is refused here, before harvesters loads it: harvesters calls the missing
``GCInitLib`` through a null pointer and the process dies (SIGSEGV, tried with a shared library that is no
producer). So the file must exist, load as a shared library and export :data:`GENTL_FUNCTIONS`.

The device is chosen by serial number (``devices.camera.serial``) or user id (``user_id``, the name a person gave
the camera, GenICam's ``DeviceUserID``); with neither, the first device found. A device not found is a
:class:`DeviceDisconnected` naming what was found, so that a reconnect waits for it.
"""

from __future__ import annotations

import ctypes
import importlib.util
import logging
import os
import time
from dataclasses import dataclass
from pathlib import Path

from rangekit.errors import DeviceDisconnected, DeviceError, one_line, shown

__all__ = ["GENTL_ENV", "GENTL_FUNCTIONS", "DeviceEntry", "shipped_producer", "producer_files", "check_producer",
           "open_harvester", "device_entries", "choose_device", "search_device", "describe"]

#: The GenTL standard's list of producer folders (64-bit processes).
GENTL_ENV = "GENICAM_GENTL64_PATH"
#: The GenTL functions a producer must export to be loaded (a subset of the standard's; every producer has them).
GENTL_FUNCTIONS = ("GCInitLib", "GCCloseLib", "TLOpen", "TLUpdateInterfaceList", "TLOpenInterface", "IFUpdateDeviceList",
                   "IFOpenDevice", "DevOpenDataStream", "DSAnnounceBuffer", "DSQueueBuffer", "DSStartAcquisition")


@dataclass(frozen=True)
class DeviceEntry:
    """A device a producer lists: its index in harvesters' ``device_info_list``, serial number, user id (None when
    the device has none), model, vendor and the producer's id of it."""

    index: int
    serial: str | None
    user_id: str | None
    model: str
    vendor: str
    id: str


def shipped_producer() -> str | None:
    """The simulated producer the ``genicam`` wheel ships (``genicam/viky.cti``: three devices, 400x400 frames at
    20 fps), or None when this platform's wheel has none. Found without importing genicam."""
    spec = importlib.util.find_spec("genicam")
    for folder in (spec.submodule_search_locations or []) if spec else []:
        path = Path(folder) / "viky.cti"
        if path.is_file():
            return str(path)
    return None


def _hint() -> str:
    shipped = shipped_producer()
    return f" (the genicam wheel's simulated cameras: {shipped})" if shipped else ""


def check_producer(path: str, what: str) -> str:
    """``path`` if it is a GenTL producer (module docstring); else a :class:`DeviceError` naming ``what`` (where the
    path came from) and what to check."""
    p = Path(path)
    if not p.exists():
        raise DeviceError(f"{what}: {str(p)!r} does not exist; give the path of the camera maker's GenTL producer "
                          f"(.cti file){_hint()}")
    if not p.is_file():
        raise DeviceError(f"{what}: {str(p)!r} is not a file; give the path of a GenTL producer (.cti file){_hint()}")
    try:
        lib = ctypes.CDLL(str(p.resolve()))
    except OSError as exc:
        raise DeviceError(f"{what}: {str(p)!r} is not a GenTL producer: it does not load as a shared library "
                          f"({one_line(exc)}); give the camera maker's .cti file for this platform{_hint()}") from None
    missing = [f for f in GENTL_FUNCTIONS if not hasattr(lib, f)]
    if missing:
        raise DeviceError(f"{what}: {str(p)!r} is not a GenTL producer: it lacks the GenTL functions "
                          f"{', '.join(missing[:3])}{', ...' if len(missing) > 3 else ''}; give the camera maker's "
                          f".cti file{_hint()}")
    return str(p)


def producer_files(producer: str | None, *, where: str) -> tuple[str, ...]:
    """The checked producer files: ``producer`` (the rig file's ``devices.camera.producer``) or those of
    ``GENICAM_GENTL64_PATH``. A DeviceError naming where the path came from when there is none or one is bad."""
    if producer is not None:
        return (check_producer(producer, f"{where}: devices.camera.producer"),)
    entries = [e for e in os.environ.get(GENTL_ENV, "").split(os.pathsep) if e.strip()]
    files: list[str] = []
    for entry in entries:
        p = Path(entry)
        found = sorted(str(f) for f in p.glob("*.cti")) if p.is_dir() else [entry]
        files += [check_producer(f, f"{GENTL_ENV} entry {shown(entry)}") for f in found]
    if not files:
        said = f"{GENTL_ENV}={shown(os.environ.get(GENTL_ENV, ''))} names no .cti file" if entries else \
            f"{GENTL_ENV} is not set"
        raise DeviceError(f"{where}: no GenTL producer: devices.camera.producer is null and {said}; set either to "
                          f"the camera maker's .cti{_hint()}")
    return tuple(dict.fromkeys(files))


def _harvesters():
    """harvesters' ``Harvester`` class; its own loggers silenced (they print tracebacks of what this driver reports
    as one line)."""
    from harvesters.core import Harvester

    for name in ("harvesters", "harvesters.core"):
        logging.getLogger(name).setLevel(logging.CRITICAL + 1)
    return Harvester


def open_harvester(files: tuple[str, ...]):
    """A harvesters ``Harvester`` with the producer ``files`` loaded and its device list read."""
    harvester = _harvesters()()
    for f in files:
        harvester.add_file(f)
    harvester.update()
    return harvester


def _info(info, name: str) -> str | None:
    """One field of a harvesters ``DeviceInfo``; None where the producer does not give it (GenTL NotAvailable)."""
    try:
        value = getattr(info, name)
    except Exception:  # noqa: BLE001 - genicam raises its own NotAvailableException for a field a device lacks
        return None
    return None if value in (None, "") else str(value)


def device_entries(harvester) -> list[DeviceEntry]:
    """The devices ``harvester``'s producers list now."""
    return [DeviceEntry(i, _info(d, "serial_number"), _info(d, "user_defined_name"), _info(d, "model") or "?",
                        _info(d, "vendor") or "?", _info(d, "id_") or "?")
            for i, d in enumerate(harvester.device_info_list)]


def describe(entry: DeviceEntry) -> str:
    """How an error names a device: ``serial 1 (Viky VikyTL_DEV_green)``."""
    user = f", user id {entry.user_id!r}" if entry.user_id else ""
    return f"serial {entry.serial} ({entry.model} {entry.id}{user})"


def choose_device(entries: list[DeviceEntry], serial: str | None, user_id: str | None) -> DeviceEntry | None:
    """The entry of serial number ``serial`` or user id ``user_id`` (the first entry when both are None)."""
    for e in entries:
        if (serial is None or e.serial == serial) and (user_id is None or e.user_id == user_id):
            return e
    return None


def search_device(files: tuple[str, ...], serial: str | None, user_id: str | None, timeout_s: float, *, where: str):
    """(harvester, entry) of the chosen device, the producers' device lists read again every 0.2 s for up to
    ``timeout_s`` seconds. DeviceDisconnected naming the devices found when it is not there."""
    deadline = time.monotonic() + float(timeout_s)
    harvester = open_harvester(files)
    try:
        while True:
            entries = device_entries(harvester)
            entry = choose_device(entries, serial, user_id)
            if entry is not None:
                return harvester, entry
            if time.monotonic() >= deadline:
                break
            time.sleep(min(0.2, max(0.0, deadline - time.monotonic())))
            harvester.update()
    except BaseException:
        harvester.reset()
        raise
    harvester.reset()
    wanted = " and ".join([*([f"serial {serial!r}"] if serial is not None else []),
                           *([f"user id {user_id!r}"] if user_id is not None else [])]) or "any device"
    found = "; ".join(describe(e) for e in entries) or "none"
    raise DeviceDisconnected(f"{where}: genicam camera with {wanted} not found within {timeout_s:g} s on "
                             f"{', '.join(files)}; found: {found}; check its cable and power, and "
                             "devices.camera.serial / user_id (rangekit devices lists the cameras)")
