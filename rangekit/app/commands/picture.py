"""A shaded picture of a mesh or point cloud file from one or more sides: the work behind ``rangekit render``."""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np

from rangekit._runtime.arguments import check_bool, check_items, check_number, check_path, check_vector, refuse
from rangekit.budget import MAX_IMAGE_SIDE_PX, check_budget
from rangekit.errors import FileFormatError, MeshError

__all__ = ["Picture", "render", "render_file"]

MESH_SUFFIXES = (".obj", ".stl", ".off", ".glb", ".gltf")


@dataclass(frozen=True, eq=False)
class Picture:
    image: np.ndarray   # (H, W, 3) uint8; several sides as a montage of up to 4 columns
    is_mesh: bool       # a mesh (vertices) or a cloud (points)
    n_points: int       # vertices or points
    n_views: int


def _ply_has_faces(path: Path) -> bool:
    """True if ``path`` is a PLY whose header declares at least one face."""
    with open(path, "rb") as f:
        head = f.read(4096)
    if not head.startswith(b"ply"):
        return False
    m = re.search(rb"element\s+face\s+(\d+)", head.split(b"end_header")[0])
    return bool(m and int(m.group(1)) > 0)


def render_file(path: str | Path, **kwargs) -> Picture:
    """:func:`render` of a mesh or point cloud file (the work behind ``rangekit render``)."""
    return render(Path(path), **kwargs)


def _is_mesh_object(x) -> bool:
    from rangekit.surface.mesh import TriangleMesh

    if isinstance(x, tuple) and len(x) == 2:  # (vertices, triangles)
        return np.asarray(x[1]).dtype.kind in "iu"
    return isinstance(x, TriangleMesh) or type(x).__name__ in ("TriangleMesh", "Trimesh", "Scene")


def _check_view(azimuths, elevation, size, up, colour) -> None:
    """:func:`render`'s arguments but ``x``, each on its own."""
    for k, azimuth in enumerate(check_items("azimuths", azimuths, "a list of angles (radians)", min_items=1)):
        check_number(f"azimuths[{k}]", azimuth, unit="radians")
    check_number("elevation", elevation, unit="radians")
    sides = check_items("size", size, "(width, height) in pixels")
    if len(sides) != 2:
        refuse("size", size, "(width, height) in pixels")
    for side in sides:
        check_number("size", side, lo=1, hi=MAX_IMAGE_SIDE_PX, integer=True, unit="pixels")
    check_vector("up", up, 3, nonzero=True)
    check_bool("colour", colour)


def render(x, *, azimuths: Sequence[float] = (np.radians(30.0),),
           elevation: float = np.radians(25.0), size: tuple[int, int] = (800, 600),
           up: Sequence[float] = (0.0, 0.0, 1.0), colour: bool = False) -> Picture:
    """Render a mesh (ray cast; ``colour``: with its vertex colours) or a cloud (z-buffer splats), framed
    tightly, from each azimuth (radians about ``up``) at ``elevation`` (radians above the horizontal).

    ``x`` is a mesh or cloud file (``str`` or ``Path``; a PLY with faces is a mesh), or an object: any mesh
    :func:`rangekit.surface.convert.as_mesh` takes (TriangleMesh, Open3D, trimesh, a (vertices, triangles)
    pair) or any cloud :func:`rangekit.surface.convert.as_cloud` takes ((N, 3) array, PointCloud, Open3D,
    trimesh). The picture is ``Picture.image``, (H, W, 3) uint8.

    Raises
    ------
    FileFormatError
        No such file, or nothing in it to render.
    InputError
        An object that is neither a mesh nor a cloud, naming its type.
    """
    from rangekit.rendering.snapshot import (CLOUD_RENDER_BYTES_PER_PIXEL, MESH_RENDER_BYTES_PER_PIXEL, fit_camera, montage,
                                       render_cloud, render_mesh)
    from rangekit.regular_files import check_regular_file
    from rangekit.surface.convert import as_cloud, as_mesh

    _check_view(azimuths, elevation, size, up, colour)
    mesh = cloud = None
    if isinstance(x, (str, os.PathLike)):
        src = Path(check_path("x", x, what="a mesh or point cloud file"))
        if src.is_dir():
            raise FileFormatError(f"{src}: is a folder, expected a mesh or a point cloud file")
        check_regular_file(src, what="a mesh or a point cloud file")
        is_mesh = src.suffix.lower() in MESH_SUFFIXES or _ply_has_faces(src)
    else:
        src = "render"
        is_mesh = _is_mesh_object(x)
        if is_mesh:
            mesh = as_mesh(x, "render x")
        else:
            cloud = as_cloud(x, "render x")
    w, h = (int(v) for v in size)
    per_px = MESH_RENDER_BYTES_PER_PIXEL if is_mesh else CLOUD_RENDER_BYTES_PER_PIXEL
    kind = "mesh" if is_mesh else "cloud"
    check_budget(w * h * (per_px + 6 * len(azimuths)),  # one render at a time; the images and their montage
                 f"rendering a {kind} from {len(azimuths)} side(s)", option=f"--size {w}x{h}")
    if is_mesh and mesh is None:
        from rangekit.formats.meshes import load_mesh

        mesh = load_mesh(src)
    elif cloud is None and mesh is None:
        from rangekit.formats.clouds import load_cloud

        cloud = load_cloud(src)
    pts = mesh.vertices if mesh is not None else cloud.points
    if len(pts) == 0:
        raise FileFormatError(f"{src}: holds no points or vertices to render")
    if mesh is not None and not mesh.area > 0:  # ray casting would see nothing: a blank picture
        raise MeshError(f"{src}: nothing to render: its {len(mesh.triangles)} triangle(s) all have zero area "
                        "(expected at least one with three vertices not on one line)")
    up = np.asarray(up, dtype=np.float64)
    images = []
    for az in azimuths:
        cam = fit_camera(pts, azimuth=az, elevation=elevation, size=size, up=up, tight=True, margin=1.1)
        images.append(render_mesh(mesh, cam, smooth=True, colour_by_vertex=colour) if mesh is not None
                      else render_cloud(cloud, cam))
    image = images[0] if len(images) == 1 else montage(images, cols=min(len(images), 4))
    return Picture(image, mesh is not None, len(pts), len(images))
