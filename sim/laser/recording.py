"""Simulated laser recordings in a laser layout (:mod:`rangekit.formats.layouts.laser`), with their truth: what a
Ciclop/Horus/FabScan-style rig (one camera, line lasers, a turntable) would have recorded, for
``rangekit calibrate --lasers --captures`` and ``rangekit reconstruct --pattern laser:...`` to read as a user's.

- :func:`write_scan_recording`: an object turned step by step, each step's laser-off frame and one frame per laser
  (:class:`rangekit.sim.laser.frames.LaserView`, as the simulated laser scan renders them);
- :func:`write_board_recordings`: the calibration board standing on the turntable, leaning back, turned through
  a sweep of angles (:func:`rangekit.sim.laser.board.turntable_board_scene_laser`), one folder per sweep: the
  laser-off frames show the board (its corners: the camera and the turntable axis), the laser frames the lines
  across it (the laser planes). Several sweeps with other tilts and offsets make the camera calibration's poses
  differ.

Beside the frames, the truth: :data:`TRUE_RIG_FILE` (the simulator's rig: camera, lasers, turntable) and
:data:`TRUTH_FILE` (kind, object, seed, the step angles, the board's placement). A real recording has neither; the
readers never look at them (only :func:`recording_truth` does, for the figures against the truth).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from rangekit.boards import Board
from rangekit.errors import FileFormatError, SceneError
from rangekit.formats.layouts.laser import STEPS_FILE, laser_layout, steps_table_text
from rangekit.io import atomic_write_json, atomic_write_text, read_json, write_png
from rangekit.progress import call_progress
from rangekit.rig.rig_file import Rig, load_rig, save_rig

__all__ = ["TRUTH_FILE", "TRUE_RIG_FILE", "RECORDING_KIND", "write_scan_recording", "write_board_recordings",
           "RecordingTruth", "recording_truth", "DEFAULT_SWEEPS"]

TRUTH_FILE = "truth.json"
TRUE_RIG_FILE = "true-rig.json"
RECORDING_KIND = "rangekit.sim.laser_recording/1"
#: The board sweeps :func:`write_board_recordings` writes by default: (tilt deg, offset m, angles deg).
DEFAULT_SWEEPS = ((15.0, 0.03, tuple(np.linspace(-30, 30, 7))), (30.0, 0.05, tuple(np.linspace(-30, 30, 7))),
                  (45.0, 0.02, tuple(np.linspace(-30, 30, 7))))


def _write_step(view, out: Path, layout, step: int, n_lasers: int, off: bool) -> None:
    if off:
        write_png(layout.frame_path(out, step, "off", n_lasers, off), view.off())
    for k in range(n_lasers):
        write_png(layout.frame_path(out, step, f"laser{k}", n_lasers, off), view.frame(k).image)


def _prepare(out: Path, layout, n_lasers: int, off: bool):
    layout = laser_layout(layout)
    if layout.n_lasers is not None and layout.n_lasers != n_lasers:
        raise SceneError(f"{layout.name} holds {layout.n_lasers} laser(s) a step; the rig has {n_lasers}")
    if layout.off is not None and layout.off != off:
        off = layout.off
    out.mkdir(parents=True, exist_ok=True)
    if (out / TRUTH_FILE).is_file():        # a recording this module wrote: its old frames go (fewer steps now)
        for old in [*out.glob("[0-9][0-9][0-9][0-9][0-9].png"), *out.glob("off/*.png"), *out.glob("laser[0-9]/*.png")]:
            old.unlink()
        (out / STEPS_FILE).unlink(missing_ok=True)
    if layout.folders:
        for kind in layout.kinds(n_lasers, off):
            (out / kind).mkdir(exist_ok=True)
    return layout, off


def _angles_table(out: Path, angles_deg: np.ndarray, table: bool | None) -> None:
    """steps.csv when ``table`` (None: when the steps are not uniform)."""
    d = np.diff(angles_deg)
    uniform = len(d) == 0 or (np.allclose(d, d[0], atol=1e-9) and abs(angles_deg[0]) < 1e-12)
    if table or (table is None and not uniform):
        atomic_write_text(out / STEPS_FILE, steps_table_text(angles_deg))


def write_scan_recording(out: str | Path, angles_deg: Sequence[float], *, obj: str = "lumpy", rig: Rig | None = None,
                         layout: str = "laser:folders", off: bool = True, seed: int = 0, imaging=None,
                         ambient_scale: int = 4, table: bool | None = None, progress: Callable | None = None) -> Path:
    """An object (``obj``: built-in name or mesh file, :func:`rangekit.sim.scene.scene.default_scene`) on ``rig``
    (default :func:`rangekit.sim.laser.rig.laser_rig`) recorded at turntable ``angles_deg`` in ``layout``, with
    (``off``) or without the laser-off frames; ``steps.csv`` when ``table`` (None: when the steps are not uniform
    from 0). ``ambient_scale``: :class:`LaserView`'s (4, as the simulated scan). Returns ``out``."""
    from rangekit.sim.laser.frames import LaserView
    from rangekit.sim.laser.rig import laser_rig
    from rangekit.sim.scene.scene import default_scene

    rig = rig if rig is not None else laser_rig()
    out = Path(out)
    layout, off = _prepare(out, layout, len(rig.lasers), off)
    angles = np.asarray(angles_deg, dtype=np.float64)
    scene = default_scene(obj)
    for i, a in enumerate(angles):
        call_progress(progress, f"rendering step {i + 1}/{len(angles)}", i, len(angles))
        view = LaserView(scene, rig, math.radians(a), imaging=imaging, seed=seed, ambient_scale=ambient_scale)
        _write_step(view, out, layout, i, len(rig.lasers), off)
    call_progress(progress, f"rendered {len(angles)} steps", len(angles), len(angles))
    _angles_table(out, angles, table)
    save_rig(rig, out / TRUE_RIG_FILE)
    atomic_write_json(out / TRUTH_FILE, {"kind": RECORDING_KIND, "what": "scan", "object": str(obj), "seed": int(seed),
                                         "layout": layout.name, "angles_deg": angles.tolist()})
    return out


def write_board_recordings(out: str | Path, *, rig: Rig | None = None, board: Board | None = None,
                           sweeps=DEFAULT_SWEEPS, layout: str = "laser:folders", seed: int = 0, imaging=None,
                           ambient_scale: int = 1, progress: Callable | None = None) -> list[Path]:
    """The board standing on the turntable, one sweep of turntable angles per folder ``sweep_1``, ``sweep_2``, ...
    in ``out`` (module doc). ``sweeps``: (tilt deg, offset m, angles deg) each. Room light of
    :data:`rangekit.sim.laser.board.CALIBRATION_LOOK` (the corners are found in the laser-off frames);
    ``ambient_scale`` 1 renders the board's texture at full resolution. Returns the sweep folders."""
    from rangekit.sim.laser.board import CALIBRATION_LOOK, turntable_board_scene_laser
    from rangekit.sim.laser.frames import LaserView
    from rangekit.sim.laser.rig import laser_rig

    rig = rig if rig is not None else laser_rig()
    board = board if board is not None else Board()
    out = Path(out)
    folders, total, done = [], sum(len(s[2]) for s in sweeps), 0
    for j, (tilt, offset, angles) in enumerate(sweeps):
        folder = out / f"sweep_{j + 1}"
        lay, off = _prepare(folder, layout, len(rig.lasers), True)
        scene = turntable_board_scene_laser(rig, board, tilt_deg=tilt, offset=offset)
        for i, a in enumerate(angles):
            call_progress(progress, f"rendering board sweep {j + 1}, step {i + 1}", done, total)
            view = LaserView(scene, rig, math.radians(a), imaging=imaging, look=CALIBRATION_LOOK,
                             seed=seed * 1000 + 100 * j + i, ambient_scale=ambient_scale)
            _write_step(view, folder, lay, i, len(rig.lasers), off)
            done += 1
        angles = np.asarray(angles, dtype=np.float64)
        _angles_table(folder, angles, True)
        save_rig(rig, folder / TRUE_RIG_FILE)
        atomic_write_json(folder / TRUTH_FILE, {
            "kind": RECORDING_KIND, "what": "board", "board": {"cols": board.cols, "rows": board.rows,
                                                              "square": board.square, "kind": board.kind},
            "tilt_deg": float(tilt), "offset_m": float(offset), "seed": int(seed), "layout": lay.name,
            "angles_deg": angles.tolist()})
        folders.append(folder)
    call_progress(progress, f"rendered {total} board steps", total, total)
    return folders


@dataclass(frozen=True, eq=False)
class RecordingTruth:
    """A simulated recording's truth: the true ``rig``, the ``object`` (scan recordings) and ``info`` (truth.json)."""

    rig: Rig
    object: str | None
    info: dict

    def object_mesh(self, angle: float = 0.0):
        """The true object's surface (a :class:`rangekit.surface.mesh.TriangleMesh`, the table left out) in the
        true world with the turntable at ``angle`` radians."""
        from rangekit.geometry import apply_T
        from rangekit.sim.scene.scene import default_scene
        from rangekit.surface.mesh import TriangleMesh

        ob = default_scene(self.object).objects[0]
        V = ob.world_vertices()
        if self.rig.T_world_table is not None:
            V = apply_T(self.rig.T_world_rotated(angle), V)
        return TriangleMesh(V, ob.triangles)


def recording_truth(folder: str | Path) -> RecordingTruth | None:
    """The truth beside a simulated recording (module doc); None for a recording without it (a real one)."""
    folder = Path(folder)
    if not (folder / TRUTH_FILE).is_file() or not (folder / TRUE_RIG_FILE).is_file():
        return None
    info = read_json(folder / TRUTH_FILE, what="a simulated recording's truth")
    if not isinstance(info, dict) or info.get("kind") != RECORDING_KIND:
        raise FileFormatError(f"{folder / TRUTH_FILE}: kind: expected {RECORDING_KIND!r}")
    return RecordingTruth(load_rig(folder / TRUE_RIG_FILE), info.get("object"), info)
