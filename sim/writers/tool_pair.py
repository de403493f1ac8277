"""A two-camera capture in another tool's layout (OpenCV's structured-light sample: ``pattern_cam1_im1.png ...`` and
``pattern_cam2_im1.png ...``), each camera under the tool's frames, with both cameras' exact truth.

``crossed=True`` writes each camera's frames under the other camera's names, the way a real capture of issue 47
was named: what the rig check's exchanged pairing (:func:`rangekit.stereo.coded_pair.pair_cameras`) must catch.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import cv2

from rangekit.camera import PinholeCamera
from rangekit.errors import StorageError
from rangekit.formats.layouts import LAYOUTS, tool_frames
from rangekit.rig.rig_file import Rig
from rangekit.sim.devices.sim_rig import SimRig
from rangekit.sim.imaging.render import ImagingModel
from rangekit.sim.scene.scene import Scene, default_scene
from rangekit.sim.scene.raycast import ViewGeometry

__all__ = ["write_tool_pair"]


def write_tool_pair(folder: str | Path, preset: str, rig: Rig, cameras: tuple[PinholeCamera, PinholeCamera], *,
                    scene: Scene | None = None, crossed: bool = False, seeds: tuple[int, int] = (3, 4),
                    imaging: ImagingModel | None = None) -> tuple[ViewGeometry, ViewGeometry]:
    """Render ``cameras`` under ``rig``'s projector and the ``preset`` layout's frames (its projector size) into
    ``folder`` under the tool's names (camera ``k`` as ``{camera}`` = k + 1, or 2 - k when ``crossed``); returns
    each camera's ground truth, in ``cameras``' order."""
    layout = LAYOUTS[preset]
    if "{camera}" not in layout.file_name:
        raise StorageError(f"{preset}: its names ({layout.file_name}) carry no camera; a two-camera capture needs them")
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    frames = tool_frames(layout, rig.projector.width, rig.projector.height)
    scene = scene if scene is not None else default_scene()
    truths = []
    for k, (camera, seed) in enumerate(zip(cameras, seeds)):
        sim = SimRig(scene, replace(rig, cameras=(camera,)), imaging=imaging or ImagingModel(), seed=seed)
        number = 2 - k if crossed else k + 1
        for i, image in enumerate(sim.capture_sequence(frames)):
            path = folder / layout.file_name.format(index=i + layout.first_index, camera=number)
            if not cv2.imwrite(str(path), image):
                raise StorageError(f"{path}: could not write the frame")
        truths.append(sim.ground_truth())
    return truths[0], truths[1]
