"""Fusion of views into one surface (Fusiello ch. 15): screened Poisson and TSDF.

- :func:`poisson_mesh`: screened Poisson reconstruction (Kazhdan & Hoppe 2013, via Open3D) of a merged,
  oriented point cloud. Vertices whose Poisson density (number of samples supporting them) is in the
  lowest ``density_quantile`` are trimmed: that is the "balloon" Poisson invents where there is no data.
- :func:`tsdf_fuse`: truncated signed distance fusion (Curless & Levoy 1996) of organised depth maps
  into a uniform voxel grid (Open3D ``UniformTSDFVolume``), then marching cubes.

Both end, by default, in :func:`rangekit.surface.watertight.make_watertight`. Units are metres.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from rangekit.camera import PinholeCamera, pixel_rays
from rangekit.errors import InputError, MeshError
from rangekit.geometry import transform_vectors
from rangekit._runtime.arguments import check_bool, check_number
from rangekit._runtime.memory import release_free_memory
from rangekit.surface.cloud import PointCloud, spread_problem
from rangekit.surface.cloud import cloud_to_open3d as _cloud_to_open3d
from rangekit.surface.convert import as_cloud
from rangekit.surface.mesh import TriangleMesh, mesh_from_open3d
from rangekit.surface.observed import OBSERVED_FACTOR, FusedMeshes, observed_rule
from rangekit.surface.tsdf_volume import integrate_view, tsdf_volume

# rangekit.surface.watertight (numba's kernels, 90 MB with scipy) is imported where a surface is closed:
# Poisson's child process (rangekit.app.process.process) imports this module and never closes one.

__all__ = ["poisson_mesh", "poisson_meshes", "poisson_surfaces", "poisson_input", "poisson_input_problem", "tsdf_fuse"]

#: Fewest oriented points :func:`poisson_mesh` accepts.
MIN_POISSON_POINTS = 10


def poisson_input_problem(points: np.ndarray, *, watertight: bool = True,
                          noun: tuple[str, str] = ("finite point", "finite points")) -> str | None:
    """Why :func:`poisson_mesh` cannot mesh ``points`` (N, 3), or None: fewer than 10 finite points, or
    points all at one point or on one line (no surface), or all in one plane when ``watertight`` (a closed
    surface of them would enclose nothing)."""
    return spread_problem(points, min_points=MIN_POISSON_POINTS, dimension=3 if watertight else 2, noun=noun)



def poisson_mesh(cloud: PointCloud, *, depth: int = 9, density_quantile: float = 0.02, watertight: bool = True,
                 n_threads: int = 1) -> TriangleMesh:
    """Screened Poisson surface of an oriented point cloud, trimmed where unsupported and closed again.

    Parameters
    ----------
    cloud : PointCloud (or any cloud :func:`rangekit.surface.convert.as_cloud` takes: an (N, 6) array, Open3D's,
        a mesh's vertices) with ``normals`` (unit, pointing out of the object, e.g. from
        :func:`rangekit.coded.triangulate.range_normals` per view or :func:`rangekit.surface.cloud.orient_normals_to_sensor`).
        Colours, if present, are carried to the vertices.
    depth : octree depth; the finest cell is ``1.1 * bounding-cube side / 2**depth``. Each step up
        roughly quadruples the vertex count and the run time. Choose the cell near the point spacing.
    density_quantile : vertices whose Poisson density is below this quantile of all densities are
        removed (0 keeps everything: Poisson's own closed but invented surface where there is no data).
    watertight : close the holes the trimming opened with :func:`make_watertight`; otherwise return the
        cleaned, trimmed (open) surface.
    n_threads : Open3D threads, -1 for all. Default 1: Open3D's Poisson on more than one thread now and then
        dies of a segmentation fault, taking the Python process with it (Open3D issue #6828; here, calling it in
        a loop on the 134-point sphere of tests/formats/test_formats_roundtrip.py at depth 5: 2 crashes in at most
        700 calls with -1, none in 2000 with 1), and its surface differs from run to run (docs/benchmarks.md).

    Returns
    -------
    TriangleMesh in the cloud's frame, outward-facing triangles.

    Raises
    ------
    MeshError
        If fewer than 10 points have finite coordinates and normals, or they are all on one line (all in
        one plane when ``watertight``): see :func:`poisson_input_problem`.
    InputError
        If the cloud has no normals. Normals are not estimated here on
        purpose: on a cloud merged from many views their sign cannot be recovered reliably; orient them
        towards the sensor per view before merging.
    """
    cloud = as_cloud(cloud, "poisson_mesh cloud")
    mesh, _, _ = _poisson_surface(cloud, depth, density_quantile, watertight, n_threads)
    from rangekit.surface.watertight import clean_mesh, make_watertight

    return make_watertight(mesh) if watertight else clean_mesh(mesh, fill=False)


def _poisson_surface(cloud: PointCloud, depth: int, density_quantile: float, watertight: bool,
                     n_threads: int) -> tuple[TriangleMesh, TriangleMesh, PointCloud]:
    """The density-trimmed (open) Poisson surface, the untrimmed one, and the cloud they were made of (finite
    points with a normal)."""
    check_number("depth", depth, lo=1, hi=12, integer=True)
    check_number("density_quantile", density_quantile, lo=0, hi=1, hi_open=True)
    check_bool("watertight", watertight)
    check_number("n_threads", n_threads, lo=-1, integer=True, unit="-1: all")
    if not isinstance(cloud, PointCloud):
        raise InputError(f"poisson_mesh: expected a rangekit PointCloud, found {type(cloud).__name__}")
    if cloud.normals is None:
        raise InputError("poisson_mesh: the cloud has no normals; Poisson needs oriented normals. Compute them "
                         "per view with rangekit.coded.triangulate.range_normals(xyz, camera.center) (or estimate them "
                         "and call orient_normals_to_sensor) before merging the views")
    ok = poisson_input(cloud)
    problem = poisson_input_problem(cloud.points[ok], watertight=watertight,
                                    noun=("point with a normal", "points with a normal"))
    if problem:
        raise MeshError(f"cannot build a {'closed ' if watertight else ''}surface: {problem}"
                        + (f" ({len(cloud)} points, {len(cloud) - np.count_nonzero(ok)} of them with a NaN, "
                           "infinite or zero coordinate or normal)" if not ok.all() else ""))
    if not ok.all():
        cloud = PointCloud(cloud.points[ok], None if cloud.colours is None else cloud.colours[ok], cloud.normals[ok])

    import open3d as o3d

    # Screened Poisson: indicator function whose gradient fits the normals, iso-surface at the samples.
    m, density = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(
        _cloud_to_open3d(cloud), depth=int(depth), n_threads=int(n_threads))
    release_free_memory()   # the octree (about 0.5 GB at depth 9) is freed: do not stack the next stage on it
    density = np.asarray(density)
    full = mesh_from_open3d(m)
    # Trim the balloon: vertices few samples support.
    if density_quantile > 0 and len(density):
        m.remove_vertices_by_mask(density < np.quantile(density, density_quantile))
    mesh = mesh_from_open3d(m)
    if len(mesh.triangles) == 0:
        raise MeshError(f"poisson_mesh: Poisson at depth {depth} gave no surface for {len(cloud)} points; "
                            "check that the normals point out of the object")
    return mesh, full, cloud


def poisson_meshes(cloud: PointCloud, *, depth: int = 9, density_quantile: float = 0.02, n_threads: int = 1,
                   spacing: np.ndarray | None = None, factor: float = OBSERVED_FACTOR) -> FusedMeshes:
    """Screened Poisson (as :func:`poisson_mesh`) split into what the views saw and the closed surface.

    ``observed``: Poisson's surface without every vertex farther than ``factor`` local point spacings from
    all of the cloud's points (and the triangles touching one): no balloon, no web across a gap no view
    saw. It is not trimmed by density: sparse but observed parts (undersides seen at grazing angles) have
    a low density, and on the 12-view lumpy scan the density trim opened holes there (completeness 96.3%
    of the visible surface against 99.7%). ``watertight``: the density-trimmed surface closed by
    :func:`make_watertight` (as :func:`poisson_mesh`), each vertex flagged ``observed`` or not by the same rule. ``spacing`` (N,) per point of ``cloud`` (metres), default
    the mean distance to its 6 nearest neighbours (see :func:`rangekit.surface.observed.observed_vertices`).
    In steps, for a caller that works on the observed mesh while the closed one is made:
    :func:`poisson_surfaces`, :func:`poisson_input` and :func:`rangekit.surface.observed.observed_rule`.

    Raises as :func:`poisson_mesh` (MeshError, InputError).
    """
    if spacing is not None and np.shape(spacing) != (len(cloud),):
        raise InputError(f"poisson_meshes: spacing must be ({len(cloud)},), one per point, found {np.shape(spacing)}")
    full, trimmed = poisson_surfaces(cloud, depth=depth, density_quantile=density_quantile, n_threads=n_threads)
    ok = poisson_input(cloud)
    rule = observed_rule(cloud.points[ok], spacing=None if spacing is None else np.asarray(spacing)[ok], factor=factor)
    from rangekit.surface.watertight import make_watertight

    return FusedMeshes(rule.observed_part(full), rule.flagged(make_watertight(trimmed)))


def poisson_input(cloud: PointCloud) -> np.ndarray:
    """(N,) bool: the points of ``cloud`` Poisson uses (finite, with a non-zero normal)."""
    with np.errstate(invalid="ignore"):
        return np.all(np.isfinite(cloud.points), axis=1) & (np.linalg.norm(cloud.normals, axis=1) > 0)


def poisson_surfaces(cloud: PointCloud, *, depth: int = 9, density_quantile: float = 0.02,
                     n_threads: int = 1) -> tuple[TriangleMesh, TriangleMesh]:
    """Poisson's two open surfaces (the cloud's frame): the whole (untrimmed) one, which the points'
    :class:`~rangekit.surface.observed.ObservedRule` cuts to the observed mesh, and the density-trimmed
    one, which :func:`make_watertight` closes."""
    surface, full, _ = _poisson_surface(cloud, depth, density_quantile, True, n_threads)
    return full, surface


def _world_points(depth: np.ndarray, camera: PinholeCamera) -> np.ndarray:
    """(K, 3) points, in the frame of ``camera.T_world_cam``, of the pixels with a depth > 0."""
    ok = np.isfinite(depth) & (depth > 0)
    d = transform_vectors(camera.T_world_cam, pixel_rays(camera).reshape(-1, 3)[ok.reshape(-1)])
    return camera.center + (depth[ok] / (d @ camera.T_world_cam[:3, 2]))[:, None] * d


def tsdf_fuse(views: Sequence[tuple[np.ndarray, np.ndarray | None, PinholeCamera]], *,
              voxel_size: float | None = None, sdf_trunc: float | None = None, watertight: bool = True,
              max_resolution: int = 384) -> TriangleMesh:
    """Fuse organised depth maps into one mesh with a uniform TSDF volume and marching cubes.

    Parameters
    ----------
    views : sequence of ``(depth, colour, camera)``
        ``depth`` (H, W) float camera-frame z in metres (the distance along the optical axis, as
        processing stores it per view), NaN or <= 0 where invalid; ``colour`` (H, W, 3) float linear RGB
        in [0, 1] or None; ``camera`` a PinholeCamera of size W x H whose ``T_world_cam`` is that view's
        camera pose in the common frame ("world"; for a turntable scan fused in the object's frame:
        ``inv(T_motion) @ T_world_cam``). Each view is resampled on the undistorted pinhole grid (same K,
        no distortion; each pixel takes the depth of the image pixel its ray crosses), so lens
        distortion needs no special handling.
    voxel_size : metres; default the diagonal of the points' bounding box / 256.
    sdf_trunc : truncation distance in metres; default ``4 * voxel_size``.
    watertight : close holes (unseen parts) with :func:`rangekit.surface.watertight.make_watertight`.
    max_resolution : refuse grids with more voxels than this along a side. Open3D 0.20 takes 48 bytes
        per voxel: 256^3 is 0.8 GB, 384^3 2.7 GB.
        The volume is a cube around the points' bounding box, so the default voxel gives
        about 256 * (largest extent / diagonal) voxels along a side (185 for the ``lumpy`` object).

    Returns
    -------
    TriangleMesh in the common frame; vertex colours from the volume when every view has a colour image.

    Raises
    ------
    InputError
        If there are no views, a depth map or colour image does not match its camera, there are no
        valid depths, or the grid would be too fine.
    """

    views = list(views)
    if not views:
        raise InputError("tsdf_fuse: no views given")
    checked = []
    for i, view in enumerate(views):
        if len(view) != 3:
            raise InputError(f"tsdf_fuse: view {i} must be (depth, colour, camera), found {len(view)} items")
        depth, colour, camera = view
        if not isinstance(camera, PinholeCamera):
            raise InputError(f"tsdf_fuse: view {i}: camera must be a PinholeCamera, found {type(camera).__name__}")
        Z = np.asarray(depth, dtype=np.float64)
        if Z.shape != (camera.height, camera.width):
            raise InputError(f"tsdf_fuse: view {i}: depth has shape {Z.shape}; camera {camera.name!r} is "
                             f"{camera.width}x{camera.height}, so it must be ({camera.height}, {camera.width})")
        if colour is not None and np.shape(colour) != (camera.height, camera.width, 3):
            raise InputError(f"tsdf_fuse: view {i}: colour has shape {np.shape(colour)}, expected "
                             f"({camera.height}, {camera.width}, 3) or None")
        checked.append((Z, colour, camera))
    with_colour = all(c is not None for _, c, _ in checked)

    # Volume: the union bounding box of the points plus the truncation band and a margin.
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for Z, _, camera in checked:
        pts = _world_points(Z, camera)
        if len(pts):
            lo, hi = np.minimum(lo, pts.min(axis=0)), np.maximum(hi, pts.max(axis=0))
    if not np.all(hi >= lo):
        raise InputError(f"tsdf_fuse: none of the {len(checked)} views has a valid (finite) point")
    diag = float(np.linalg.norm(hi - lo))
    voxel = diag / 256 if voxel_size is None else float(voxel_size)
    if not (voxel > 0 and np.isfinite(voxel)):
        raise InputError(f"tsdf_fuse: voxel_size must be > 0, found {voxel_size!r} (points' diagonal {diag:.4g} m)")
    trunc = 4 * voxel if sdf_trunc is None else float(sdf_trunc)
    if not (trunc > 0 and np.isfinite(trunc)):
        raise InputError(f"tsdf_fuse: sdf_trunc must be > 0, found {sdf_trunc!r}")
    volume = tsdf_volume(lo, hi, voxel, trunc, colour=with_colour, max_resolution=max_resolution)
    for Z, colour, camera in checked:
        integrate_view(volume, Z, colour if with_colour else None, camera)

    mesh = mesh_from_open3d(volume.extract_triangle_mesh())
    if not with_colour:
        mesh = TriangleMesh(mesh.vertices, mesh.triangles)
    if len(mesh.triangles) == 0:
        raise MeshError(f"tsdf_fuse: the volume holds no surface after {len(checked)} views (voxel "
                            f"{voxel:.4g} m, sdf_trunc {trunc:.4g} m); check the camera poses")
    from rangekit.surface.watertight import clean_mesh, make_watertight

    return make_watertight(mesh) if watertight else clean_mesh(mesh, fill=False)

