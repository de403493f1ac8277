"""A simulated scene: objects on (or off) the turntable, flattened to one world mesh per state."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rangekit.errors import SceneError
from rangekit.geometry import apply_T, axis_angle_to_R, compose, make_T, transform_vectors
from rangekit.sim.scene.objects import make_object, turntable_disc
from rangekit.sim.scene.scene_object import SceneObject
from rangekit.sim.scene.raycast import WorldMesh

__all__ = ["Scene", "default_scene"]


@dataclass(frozen=True, eq=False)
class Scene:
    """Objects in the rig's world frame (the default rig's world is the turntable frame, z up)."""

    objects: tuple[SceneObject, ...]

    def __post_init__(self) -> None:
        if not self.objects:
            raise SceneError("a scene needs at least one object")
        object.__setattr__(self, "objects", tuple(self.objects))

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(o.name for o in self.objects)

    def world_mesh(self, T_motion: np.ndarray | None = None) -> WorldMesh:
        """All triangles in world coordinates; ``T_motion`` (4, 4) moves the objects on the turntable."""
        verts, tris, normals, albedo, spec, shin, smooth, owner = [], [], [], [], [], [], [], []
        poses = []
        offset = 0
        for i, obj in enumerate(self.objects):
            T = obj.T_world_obj if (T_motion is None or not obj.on_turntable) else compose(T_motion, obj.T_world_obj)
            poses.append(T)
            verts.append(apply_T(T, obj.vertices))
            normals.append(transform_vectors(T, obj.vertex_normals()))
            tris.append(obj.triangles + offset)
            albedo.append(obj.vertex_albedo)
            nf = len(obj.triangles)
            spec.append(np.full(nf, obj.specular))
            shin.append(np.full(nf, obj.shininess))
            smooth.append(np.full(nf, obj.smooth))
            owner.append(np.full(nf, i, dtype=np.int32))
            offset += len(obj.vertices)
        return WorldMesh(vertices=np.concatenate(verts), triangles=np.concatenate(tris).astype(np.int64),
                         vertex_normals=np.concatenate(normals), vertex_albedo=np.concatenate(albedo),
                         face_specular=np.concatenate(spec), face_shininess=np.concatenate(shin),
                         face_smooth=np.concatenate(smooth), face_object=np.concatenate(owner),
                         object_names=self.names, object_poses=tuple(poses),
                         object_textures=tuple(o.texture for o in self.objects))


def default_scene(obj: str | SceneObject = "lumpy", *, with_table: bool = True, **object_options) -> Scene:
    """The object (a built-in name, a mesh file or a SceneObject) standing on the turntable's centre.

    An object with a :class:`~rangekit.sim.scene.objects.PlanarTexture` (a calibration board, printed side
    towards its own -z) is turned over about its x axis, so it lies printed side up, and raised by 1 mm
    (a card's thickness) so its face does not coincide with the table top's.
    """
    if isinstance(obj, str):
        obj = make_object(obj, **object_options)
    placed = obj.placed_on_table()
    if obj.texture is not None:
        lo, hi = obj.vertices.min(axis=0), obj.vertices.max(axis=0)
        T = compose(placed.T_world_obj, make_T(axis_angle_to_R([1.0, 0.0, 0.0], np.pi), [0.0, lo[1] + hi[1], 0.0]))
        T[2, 3] += 1e-3 - apply_T(T, obj.vertices)[:, 2].min()
        placed = placed.with_pose(T)
    objects = [placed]
    if with_table:
        objects.append(turntable_disc())
    return Scene(tuple(objects))
