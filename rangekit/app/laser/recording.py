"""``rangekit reconstruct DIR --pattern laser:... --rig RIG.json [--step-deg DEG]``: a recorded laser-line turntable
scan (:mod:`rangekit.formats.layouts.laser`) to one cloud, both lasers merged.

Per step, as a laser session's processing (:func:`rangekit.app.process.laser.laser_profiles`): each laser's
Gaussian line peaks in laser on minus laser off (without recorded laser-off frames: the darkest of the step's
laser frames, :func:`rangekit.app.laser.recorded_calibration.ambient_frame`), looked for only where the laser's
plane lies above the turntable top; each peak's ray (with the lens distortion) met with that laser's plane; points
off a continuous run of the line and within ``table_margin`` of the table top dropped; the rest turned back by the
step's angle about the calibrated axis into the first step's frame (:func:`rangekit.rig.rig_file.turntable_prior`).

The two lasers see the object from two sides; where both saw the same surface their points should coincide.
:func:`rangekit.laser.agreement.laser_agreement` measures it: each laser's points' distance to the local plane of
the other's nearest points, where the other laser has points within ``radius``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from rangekit.errors import DecodeError
from rangekit.formats.laser_capture import LaserCapture
from rangekit.formats.layouts.laser import LaserRecording, read_step_frames
from rangekit.geometry import apply_T, invert_T
from rangekit.progress import call_progress
from rangekit.rig.rig_file import Rig, turntable_prior
from rangekit.surface.cloud import PointCloud

__all__ = ["RecordingCloud", "reconstruct_laser_recording", "recording_lines", "truth_figures"]


@dataclass(frozen=True, eq=False)
class RecordingCloud:
    """The merged ``cloud`` (world = the rig's, at the first step's angle); per point its ``step`` and ``laser``;
    per step and laser the points kept (``n_points``, (n_steps, n_lasers)); the points dropped as the table top."""

    cloud: PointCloud
    step: np.ndarray
    laser: np.ndarray
    n_points: np.ndarray
    on_table: int
    T_world_view: np.ndarray

    def summary(self) -> str:
        per = ", ".join(f"laser {k}: {int(n):,} points, no line in {int((self.n_points[:, k] == 0).sum())} step(s)"
                        for k, n in enumerate(self.n_points.sum(axis=0)))
        return (f"{len(self.cloud):,} points from {len(self.n_points)} steps ({per}); {self.on_table:,} on the table "
                "top dropped")


def reconstruct_laser_recording(recording: LaserRecording, rig: Rig, *, method: str = "gaussian",
                                table_margin: float = 0.002, progress: Callable | None = None) -> RecordingCloud:
    """Every step of ``recording`` triangulated with ``rig`` (its camera, its lasers' planes, its turntable) and
    merged (module doc).

    Raises
    ------
    FileFormatError : the rig's lasers and the recording's differ in number; a frame of another size than the
        rig's camera (named); an unreadable frame.
    DecodeError : a laser whose line is found in no step (named, with its frames).
    """
    from rangekit.app.laser.reconstruct import reconstruct_laser_capture
    from rangekit.app.laser.recorded_calibration import ambient_frame
    from rangekit.errors import FileFormatError
    from rangekit.laser.triangulate import plane_region

    cam = rig.camera
    if len(rig.lasers) != recording.n_lasers:
        raise FileFormatError(f"{recording.folder}: {recording.n_lasers} laser frame(s) a step, but the rig file has "
                              f"{len(rig.lasers)} laser(s) in 'lasers'; one frame per laser of the rig is expected")
    T_world_view = (turntable_prior(rig.T_world_table, recording.angles) if rig.T_world_table is not None
                    else np.repeat(np.eye(4)[None], len(recording.steps), axis=0))
    T_table_world = invert_T(rig.T_world_table) if rig.T_world_table is not None else None
    regions = None if T_table_world is None else [
        plane_region(cam, laser, rig.T_world_table, z_min=table_margin) for laser in rig.lasers]
    points, colours, steps, lasers, counts, on_table = [], [], [], [], [], 0
    for i, step in enumerate(recording.steps):
        call_progress(progress, f"step {i + 1}/{len(recording.steps)}", i, len(recording.steps))
        off, frames = read_step_frames(step)
        if frames[0].shape[:2] != (cam.height, cam.width):
            raise FileFormatError(f"{step.lasers[0]}: image is {frames[0].shape[1]}x{frames[0].shape[0]} but the rig "
                                  f"file's camera is {cam.width}x{cam.height}")
        capture = LaserCapture(recording.folder, rig, ambient_frame(off, frames), frames, {})
        rec = reconstruct_laser_capture(capture, method=method, require=False, regions=regions)
        P, C, which = rec.cloud.points, rec.cloud.colours, rec.laser_index
        if T_table_world is not None and len(P):
            keep = apply_T(T_table_world, P)[:, 2] > table_margin
            on_table += int((~keep).sum())
            P, C, which = P[keep], C[keep], which[keep]
        points.append(apply_T(T_world_view[i], P))
        colours.append(C)
        lasers.append(which)
        steps.append(np.full(len(P), i))
        counts.append(np.bincount(which, minlength=len(rig.lasers)))
    call_progress(progress, f"{len(recording.steps)} steps", len(recording.steps), len(recording.steps))
    n_points = np.asarray(counts, dtype=np.int64).reshape(len(recording.steps), len(rig.lasers))
    for k, laser in enumerate(rig.lasers):
        if n_points[:, k].sum() == 0:
            first, last = recording.steps[0].lasers[k], recording.steps[-1].lasers[k]
            raise DecodeError(f"laser {k} ({laser.name}): no line above the table top in any of the "
                              f"{len(recording.steps)} steps ({first} ... {last}); is it the rig file's laser {k}, "
                              "on, and aimed at the object?")
    cloud = PointCloud(np.concatenate(points), colours=np.concatenate(colours))
    return RecordingCloud(cloud, np.concatenate(steps), np.concatenate(lasers), n_points, on_table, T_world_view)


def recording_lines(recording: LaserRecording, rec: RecordingCloud) -> list[str]:
    """Lines for ``rangekit reconstruct``: where the lasers agree (two or more lasers), and on a simulated recording
    (its truth beside it, :func:`rangekit.sim.laser.recording.recording_truth`) the cloud's distance to the true
    surface, all and per laser."""
    from rangekit.errors import InputError
    from rangekit.laser.agreement import laser_agreement

    lines = []
    P = rec.cloud.points
    for k in range(1, rec.n_points.shape[1]):
        try:
            lines.append(f"lasers 0 and {k}: " + laser_agreement(P[rec.laser == 0], P[rec.laser == k]).line())
        except InputError as exc:
            lines.append(f"lasers 0 and {k}: not compared: {exc}")
    figures = truth_figures(recording, rec)
    if figures is not None:
        per = ", ".join(f"laser {k} {v * 1e3:.4f} mm" for k, v in enumerate(figures["laser_rms"]))
        lines.append(f"cloud against the true surface: RMS {figures['rms'] * 1e3:.4f} mm, 95th percentile "
                     f"{figures['p95'] * 1e3:.4f} mm over {len(P):,} points ({per})")
    return lines


def truth_figures(recording: LaserRecording, rec: RecordingCloud) -> dict | None:
    """The cloud against the simulator's truth beside the recording (None without it): ``rms``, ``p95`` and
    ``laser_rms`` (per laser), metres; the cloud (the rig's world at the first step) against the true object at the
    first step's angle in the true world."""
    from rangekit.sim.laser.recording import recording_truth
    from rangekit.surface.mesh import distance_to_surface

    truth = recording_truth(recording.folder)
    if truth is None or truth.object is None or not len(rec.cloud):
        return None
    d = distance_to_surface(rec.cloud.points, truth.object_mesh(float(recording.angles[0])))
    return {"rms": float(np.sqrt(np.mean(d ** 2))), "p95": float(np.percentile(d, 95)),
            "laser_rms": [float(np.sqrt(np.mean(d[rec.laser == k] ** 2))) if (rec.laser == k).any() else float("nan")
                          for k in range(rec.n_points.shape[1])]}
