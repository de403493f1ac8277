"""The camera drivers, one entry per ``devices.camera.type`` of a rig file: which module opens and lists the
cameras of that type, and which optional extra installs its package.

Each driver module has

- ``open_camera(section, rig, *, coded_light, where)``: the camera of a checked ``devices.camera`` section
  (:func:`rangekit.rig.checks.validate_devices`), opened with the rig's ``capture.camera`` controls;
- ``list_cameras(timeout_s) -> list[FoundCamera]``: the cameras of that type attached now (``rangekit
  devices``); [] when none is.

A driver whose package is not installed is one line naming the extra to install (:func:`camera_driver`), never a
traceback. The rig file's check knows the same types (:data:`rangekit.rig.checks.CAMERA_SECTION_FIELDS`).
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from types import ModuleType

from rangekit.errors import DeviceError

__all__ = ["CameraDriver", "FoundCamera", "CAMERA_DRIVERS", "camera_driver", "MissingPackage"]


@dataclass(frozen=True)
class CameraDriver:
    """A camera type's driver: ``module`` (imported when used), ``packages`` the Python packages it needs
    (import names), ``extra`` the ``pip install 'rangekit[EXTRA]'`` that installs them (None: required
    dependencies), ``what`` how a person names such cameras."""

    module: str
    what: str
    packages: tuple[str, ...] = ()
    extra: str | None = None


@dataclass(frozen=True)
class FoundCamera:
    """A camera ``rangekit devices`` lists: ``id`` what the rig file's section takes to choose it (serial
    number, device id, path), ``name`` the device's own name, ``detail`` anything else worth a look (state,
    interface, producer)."""

    id: str
    name: str
    detail: str = ""


class MissingPackage(DeviceError):
    """A camera driver's package is not installed: the message names the extra."""


#: The camera drivers by ``devices.camera.type``.
CAMERA_DRIVERS: dict[str, CameraDriver] = {
    "depthai": CameraDriver("rangekit.drivers.depthai.camera", "Luxonis OAK (depthai)", ("depthai",)),
    "realsense": CameraDriver("rangekit.drivers.realsense.camera", "Intel RealSense (infrared imager)",
                              ("pyrealsense2",), "realsense"),
    "uvc": CameraDriver("rangekit.drivers.uvc.camera", "UVC webcams (V4L2)", ("linuxpy",), "uvc"),
    "genicam": CameraDriver("rangekit.drivers.genicam.camera", "GenICam/GenTL machine-vision cameras (harvesters)",
                            ("harvesters", "genicam"), "genicam"),
}


def camera_driver(kind: str) -> ModuleType:
    """The driver module of camera type ``kind``; its missing package is a :class:`MissingPackage` naming the
    extra to install."""
    driver = CAMERA_DRIVERS[kind]
    for package in driver.packages:
        try:
            importlib.import_module(package)
        except ImportError as exc:
            how = f"pip install 'rangekit[{driver.extra}]'" if driver.extra else f"pip install {package}"
            raise MissingPackage(f"{kind} cameras ({driver.what}) need the Python package {package!r}, which is "
                                 f"not installed ({exc}): {how}") from None
    return importlib.import_module(driver.module)
