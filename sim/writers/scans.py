"""Simulated turntable scans with exact poses, for registration and fusion.

Each view is the object's ground-truth surface as the camera sees it at one turntable angle (plus
Gaussian noise), in the camera's world frame. The object turned by ``M_k`` (the turntable motion at
view k), so the pose that maps view k into view 0's frame is ``T_world_view[k] = M_0 @ inv(M_k)``
(:func:`rangekit.rig.rig_file.turntable_prior`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.geometry import apply_T, axis_angle_to_R, make_T
from rangekit.surface.cloud import PointCloud
from rangekit.rig.rig_file import Rig, turntable_prior
from rangekit.sim.devices.sim_rig import SimRig, default_rig
from rangekit.sim.scene.scene import default_scene

__all__ = ["TurntableScans", "turntable_scans", "perturb_poses"]


@dataclass(frozen=True, eq=False)
class TurntableScans:
    clouds: list[PointCloud]       # per view, world (camera rig) frame at capture time, with normals
    range_maps: list[np.ndarray]   # per view (H, W, 3) organised points, NaN where not the object
    normal_maps: list[np.ndarray]  # per view (H, W, 3) unit normals facing the camera
    T_world_view: np.ndarray       # (n, 4, 4) truth: view k into view 0's frame
    angles: np.ndarray             # (n,) turntable angles, radians
    rig: Rig
    object_vertices: np.ndarray    # (V, 3) the true surface in view 0's frame
    object_triangles: np.ndarray   # (F, 3)
    diag: float                    # bounding-box diagonal of the object, metres


def turntable_scans(obj: str = "lumpy", *, n_views: int = 12, noise: float = 0.0005, rig: Rig | None = None,
                    resolution: tuple[int, int] | None = None, rng: int | np.random.Generator = 0) -> TurntableScans:
    """Scan ``obj`` at ``n_views`` evenly spaced turntable angles.

    ``noise``: Gaussian sigma as a fraction of the object's bounding-box diagonal (0.0005 = 0.05%).
    ``resolution``: optional (width, height) to resize the camera (smaller is faster).
    """
    rng = np.random.default_rng(rng)
    rig = rig or default_rig()
    if resolution is not None:
        rig = Rig(cameras=(rig.camera.resized(*resolution),), projector=rig.projector,
                  T_world_table=rig.T_world_table, devices=rig.devices, capture=rig.capture)
    scene = default_scene(obj, with_table=False)
    sim = SimRig(scene, rig)
    ob = scene.objects[0]
    V = ob.world_vertices()
    diag = float(np.linalg.norm(np.ptp(V, axis=0)))
    angles = 2 * np.pi * np.arange(n_views) / n_views
    clouds, maps, nmaps = [], [], []
    M0 = rig.T_world_rotated(angles[0])
    for a in angles:
        sim.turntable.rotate_to(a)
        truth = sim.ground_truth()
        m = truth.hit
        xyz = np.where(m[:, :, None], truth.xyz, np.nan)
        xyz[m] += rng.normal(scale=noise * diag, size=(int(m.sum()), 3))
        nrm = np.where(m[:, :, None], truth.normal, np.nan)
        maps.append(xyz)
        nmaps.append(nrm)
        clouds.append(PointCloud(xyz[m], normals=nrm[m]))
    return TurntableScans(clouds, maps, nmaps, turntable_prior(rig.T_world_table, angles), angles, rig, apply_T(M0, V), ob.triangles, diag)


def perturb_poses(T_world_view: np.ndarray, *, max_angle: float, max_translation: float,
                  rng: int | np.random.Generator = 0) -> np.ndarray:
    """Each pose (but the first) moved by a random rotation up to ``max_angle`` radians and a random
    translation up to ``max_translation`` metres (uniform in size, random direction)."""
    rng = np.random.default_rng(rng)
    out = np.array(T_world_view, dtype=np.float64, copy=True)
    for k in range(1, len(out)):
        axis = rng.normal(size=3)
        d = rng.normal(size=3)
        dT = make_T(axis_angle_to_R(axis, rng.uniform(0, max_angle)),
                    d / np.linalg.norm(d) * rng.uniform(0, max_translation))
        out[k] = dT @ out[k]
    return out
