"""Point clouds with colours and normals: the type, voxel downsampling, normals, transforms and merging.

Files of clouds are read and written by :mod:`rangekit.formats.clouds`. Conversion to open3d happens in
:func:`cloud_to_open3d` only (open3d is imported inside the functions that need it).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from rangekit._runtime.arguments import as_array, as_points, check_instance, check_items, check_number, check_pose, check_vector
from rangekit.errors import InputError, MeshError

__all__ = ["PointCloud", "cloud_to_open3d", "voxel_downsample", "MAX_VOXELS_PER_DIAGONAL", "bbox_diagonal",
           "check_voxel", "estimate_normals", "downsample_with_normals", "orient_normals_to_sensor", "oriented_normals_cloud", "transform_cloud",
           "merge_clouds", "view_index", "affine_dimension", "spread_problem"]


@dataclass(frozen=True, eq=False)
class PointCloud:
    """Points in metres with optional per-point colour, unit normal and predicted uncertainty."""

    points: np.ndarray                 # (N, 3) float64 metres
    colours: np.ndarray | None = None  # (N, 3) float32 linear RGB in [0, 1]
    normals: np.ndarray | None = None  # (N, 3) float64 unit vectors
    sigma: np.ndarray | None = None    # (N,) float32 metres: predicted std of each point along its camera ray
                                       # (rangekit.coded.uncertainty); NaN where unknown

    def __post_init__(self) -> None:
        P = as_points("points", self.points)
        object.__setattr__(self, "points", P)
        for name in ("colours", "normals"):
            a = getattr(self, name)
            if a is not None:
                a = as_array(name, a, f"an {P.shape} array or None", dtype=np.float32 if name == "colours" else np.float64)
                if a.shape != P.shape:
                    raise InputError(f"PointCloud: {name} must be {P.shape}, found {a.shape}")
                object.__setattr__(self, name, a)
        if self.sigma is not None:
            sg = as_array("sigma", self.sigma, f"a ({len(P)},) array or None", dtype=np.float32)
            if sg.shape != (len(P),):
                raise InputError(f"PointCloud: sigma must be ({len(P)},), found {sg.shape}")
            object.__setattr__(self, "sigma", sg)

    def take(self, index) -> "PointCloud":
        """The points selected by ``index`` (a boolean mask or integer indices), every field kept."""
        pick = (lambda a: None if a is None else a[index])
        return PointCloud(self.points[index], pick(self.colours), pick(self.normals), pick(self.sigma))

    def __len__(self) -> int:
        return len(self.points)

    def __repr__(self) -> str:
        extra = [n for n in ("colours", "normals", "sigma") if getattr(self, n) is not None]
        return f"PointCloud({len(self)} points{', ' + ', '.join(extra) if extra else ''})"


def cloud_to_open3d(cloud: PointCloud):
    """The cloud as an ``open3d.geometry.PointCloud`` (imports open3d)."""
    import open3d as o3d

    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(cloud.points))
    if cloud.colours is not None:
        pc.colors = o3d.utility.Vector3dVector(cloud.colours.astype(np.float64))
    if cloud.normals is not None:
        pc.normals = o3d.utility.Vector3dVector(cloud.normals)
    return pc



def affine_dimension(points: np.ndarray, *, rel_tol: float = 1e-6) -> int:
    """Dimension of the smallest affine space holding the finite ``points`` (N, 3): 0 (none, one point or
    all identical), 1 (a line), 2 (a plane) or 3. A direction counts when the points spread along it by
    more than ``rel_tol`` times their largest spread (1e-6: a micrometre over a metre is flat)."""
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    P = P[np.isfinite(P).all(axis=1)]
    if len(P) < 2 or not np.ptp(P, axis=0).max() > 1e-12 * (1.0 + np.abs(P).max()):
        return 0
    Q = P - P.mean(axis=0)
    spread = np.sqrt(np.clip(np.linalg.eigvalsh(Q.T @ Q), 0.0, None))  # singular values of Q, ascending
    return int(np.count_nonzero(spread > rel_tol * spread[-1]))


_SHAPES = {0: "all at one point", 1: "all on one line", 2: "all in one plane"}


def spread_problem(points: np.ndarray, *, min_points: int, dimension: int = 3,
                   noun: tuple[str, str] = ("finite point", "finite points")) -> str | None:
    """Why ``points`` (N, 3) are too few or too flat to build a surface from, or None.

    The reason reads "need at least 10 points not all in one plane, found 3 points, all on one line":
    at least ``min_points`` finite points spanning ``dimension`` dimensions (3: not in one plane; 2: not
    on one line). ``noun`` (singular, plural) names what was counted.
    """
    P = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    n = int(np.count_nonzero(np.isfinite(P).all(axis=1)))
    dim = affine_dimension(P)
    if n >= min_points and dim >= dimension:
        return None
    need = {3: " not all in one plane", 2: " not all on one line", 1: " not all at one point"}.get(dimension, "")
    found = f"{n} {noun[n != 1]}" + (f" of {len(P)}" if n != len(P) else "")
    if dim < dimension and n > 1:
        found += f", {_SHAPES[dim]}"
    return f"need at least {min_points} points{need}, found {found}"


def voxel_downsample(points: np.ndarray, voxel: float, *,
                     normals: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """Mean point (and renormalised mean normal) per occupied voxel of edge ``voxel`` metres.

    Parameters
    ----------
    points : (N, 3) float metres.
    voxel : edge of the voxel grid in metres; ``voxel <= 0`` returns the points unchanged.
    normals : (N, 3) or None.

    Returns
    -------
    (points, normals) : (M, 3) float64 means, one row per occupied voxel (ordered by voxel key), and
    their (M, 3) unit mean normals, or None when no normals were given. Always a pair.
    """
    P = as_points("points", points)
    check_number("voxel", voxel, unit="metres")
    if normals is not None and as_points("normals", normals).shape != P.shape:
        raise InputError(f"normals: expected an {P.shape} array like points, found shape {np.shape(normals)}")
    if voxel <= 0 or len(P) == 0:
        return P, normals
    cells = np.floor(P / voxel)
    cells -= cells.min(axis=0)
    if not (np.isfinite(cells).all() and float(np.prod(cells.max(axis=0) + 1)) < 2.0**62):
        raise InputError(f"voxel_downsample: a {voxel:.3g} m voxel over points {np.ptp(P, axis=0).tolist()} m "
                         "apart makes more grid cells than 2**62; use a larger voxel (see check_voxel)")
    keys = cells.astype(np.int64)
    dims = keys.max(axis=0) + 1
    flat = (keys[:, 0] * dims[1] + keys[:, 1]) * dims[2] + keys[:, 2]
    _, inv, counts = np.unique(flat, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    m = len(counts)
    # Per-voxel sums by bincount, one column at a time (np.add.at is about 10x slower).
    out = np.stack([np.bincount(inv, weights=P[:, a], minlength=m) for a in range(3)], axis=1)
    out /= counts[:, None]
    if normals is None:
        return out, None
    N = np.asarray(normals, dtype=np.float64)
    n = np.stack([np.bincount(inv, weights=N[:, a], minlength=m) for a in range(3)], axis=1)
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    return out, n


#: The finest voxel accepted from a user (registration, fusion): the scene's bounding-box diagonal divided
#: by this (the default registration voxel is diagonal / 110); finer voxels hold one point each and only
#: make the work slower (a 1 um voxel on two Stanford bunny scans ran 90 s and failed).
MAX_VOXELS_PER_DIAGONAL = 2000


def bbox_diagonal(clouds: Sequence[PointCloud]) -> float:
    """Diagonal of the bounding box of ``clouds`` in metres (of about 2000 points of each, NaN ignored)."""
    pts = np.concatenate([np.asarray(c.points)[::max(1, len(c.points) // 2000)] for c in clouds])
    return float(np.linalg.norm(np.nanmax(pts, axis=0) - np.nanmin(pts, axis=0)))


def check_voxel(voxel, diagonal: float, *, what: str = "voxel", error: type[InputError] = InputError) -> float:
    """``voxel`` (metres) as a float when it is finite, > 0 and at least ``diagonal /``
    :data:`MAX_VOXELS_PER_DIAGONAL`; else ``error`` naming ``what``, the smallest allowed and the found value."""
    ok = isinstance(voxel, (int, float, np.floating, np.integer)) and not isinstance(voxel, bool) \
        and np.isfinite(voxel) and voxel > 0
    if ok and voxel >= diagonal / MAX_VOXELS_PER_DIAGONAL:
        return float(voxel)
    found = f"{voxel * 1e3:.4g} mm" if ok else repr(voxel)
    raise error(f"{what}: expected a voxel of at least {diagonal / MAX_VOXELS_PER_DIAGONAL * 1e3:.4g} mm (the "
                f"scene's {diagonal * 1e3:.4g} mm bounding-box diagonal / {MAX_VOXELS_PER_DIAGONAL}), found {found}")


def downsample_with_normals(cloud: PointCloud, voxel: float) -> PointCloud:
    """``cloud`` (metres) voxel-downsampled by :func:`voxel_downsample` with its normals averaged, or, when it
    has none, estimated from 20 neighbours: the points and normals registration works on."""
    p, n = voxel_downsample(np.asarray(cloud.points), voxel, normals=cloud.normals)
    return PointCloud(p, normals=n if n is not None else estimate_normals(p, k=20))


def estimate_normals(points: np.ndarray, *, k: int = 20, viewpoint: np.ndarray | None = None) -> np.ndarray:
    """(N, 3) unit normals from the k nearest neighbours (PCA via Open3D), facing ``viewpoint`` if given."""
    points = as_points("points", points)
    check_number("k", k, lo=1, integer=True)
    check_vector("viewpoint", viewpoint, 3, optional=True)
    import open3d as o3d

    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, dtype=np.float64)))
    pc.estimate_normals(o3d.geometry.KDTreeSearchParamKNN(knn=k))
    n = np.asarray(pc.normals).copy()
    if viewpoint is not None:
        flip = np.einsum("ij,ij->i", n, np.asarray(viewpoint) - points) < 0
        n[flip] *= -1
    return n


def orient_normals_to_sensor(points: np.ndarray, normals: np.ndarray, sensor_origin: np.ndarray) -> np.ndarray:
    """Flip normals so that each faces its sensor: ``n . (origin - p) > 0``.

    Parameters
    ----------
    points, normals : (N, 3) float64, same frame (metres; normals need not be unit).
    sensor_origin : (3,) or (N, 3) the optical centre(s) that saw the points, same frame.

    Returns
    -------
    (N, 3) float64 normals; rows with NaN stay NaN, rows with ``n . (origin - p) == 0`` are kept.
    """
    P = np.asarray(points, dtype=np.float64)
    N = np.asarray(normals, dtype=np.float64)
    O = np.asarray(sensor_origin, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3 or N.shape != P.shape:
        raise InputError(f"orient_normals_to_sensor: points and normals must both be (N, 3), found "
                         f"{P.shape} and {N.shape}")
    if O.shape not in ((3,), P.shape):
        raise InputError(f"orient_normals_to_sensor: sensor_origin must be (3,) or {P.shape}, found {O.shape}")
    with np.errstate(invalid="ignore"):
        flip = np.einsum("ij,ij->i", N, O - P) < 0
    out = N.copy()
    out[flip] *= -1.0
    return out


def oriented_normals_cloud(points: np.ndarray, *, voxel: float | None = None) -> PointCloud:
    """A voxel-downsampled copy of ``points`` (N, 3) with outward normals, for clouds that have none.

    Normals are estimated from 30 neighbours, pointed away from the centroid, then made consistent by
    propagation over a neighbour graph (Open3D), which also gets concave parts right where the centroid
    rule fails. ``voxel`` default: bounding-box diagonal / 400. Non-finite points are dropped.

    Raises
    ------
    MeshError
        If fewer than 4 distinct points not all in one plane are left after downsampling: "outward" needs
        an inside (and the propagation, a Delaunay tetrahedralisation in Qhull, fails on flat input).
    """
    import open3d as o3d

    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    points = points[np.isfinite(points).all(axis=1)]
    diag = float(np.linalg.norm(np.ptp(points, axis=0))) if len(points) else 0.0
    v = voxel or diag / 400
    P, _ = voxel_downsample(points, v)
    problem = spread_problem(P, min_points=4)
    if problem:
        raise MeshError(f"cannot orient normals outwards: {problem}" + (f" (after {v:.3g} m voxels)" if len(P) < len(points) else ""))
    n = estimate_normals(P, k=30)
    out = np.einsum("ij,ij->i", n, P - P.mean(axis=0)) < 0
    n[out] *= -1
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(P))
    pc.normals = o3d.utility.Vector3dVector(n)
    try:
        pc.orient_normals_consistent_tangent_plane(20)
    except RuntimeError as exc:  # Qhull on nearly flat or nearly coincident input
        raise MeshError(f"cannot orient normals outwards on {len(P)} points: the neighbour graph failed "
                        f"({str(exc).splitlines()[0][:200]}); are the points nearly all in one plane?") from None
    n = np.asarray(pc.normals)
    if np.mean(np.einsum("ij,ij->i", n, P - P.mean(axis=0)) < 0) > 0.5:  # propagation may flip all
        n = -n
    return PointCloud(P, normals=n)



def transform_cloud(cloud: PointCloud, T_a_b: np.ndarray) -> PointCloud:
    """``cloud`` (frame b) in frame a: points mapped by ``T_a_b``, normals rotated, colours and sigma kept
    (a rigid motion does not change a length)."""
    check_instance("cloud", cloud, PointCloud, "a rangekit PointCloud")
    T = check_pose("T_a_b", T_a_b)
    points = cloud.points @ T[:3, :3].T + T[:3, 3]
    normals = None if cloud.normals is None else cloud.normals @ T[:3, :3].T
    return PointCloud(points, cloud.colours, normals, cloud.sigma)


def merge_clouds(clouds: Sequence[PointCloud], T_world_view: np.ndarray | Sequence[np.ndarray]) -> PointCloud:
    """The views' clouds in one frame: view k's points mapped by ``T_world_view[k]``, normals rotated.

    Parameters
    ----------
    clouds : n PointClouds, each in its view's frame (metres).
    T_world_view : (n, 4, 4) poses of the views in the common frame.

    Returns
    -------
    PointCloud with all points in view order; normals (float64) when every view has normals, colours
    when every view has colours, sigma when every view has sigma, otherwise None.
    """
    clouds = check_items("clouds", clouds, "a list of PointClouds", min_items=1)
    for k, c in enumerate(clouds):
        check_instance(f"clouds[{k}]", c, PointCloud, "a rangekit PointCloud")
    T = check_pose("T_world_view", T_world_view, count=len(clouds))
    moved = [transform_cloud(c, Tk) for c, Tk in zip(clouds, T)]
    points = np.concatenate([c.points for c in moved])
    normals = None
    if all(c.normals is not None for c in moved):
        normals = np.concatenate([c.normals for c in moved])
    colours = None
    if all(c.colours is not None for c in moved):
        colours = np.concatenate([c.colours for c in moved])
    sigma = None
    if all(c.sigma is not None for c in moved):
        sigma = np.concatenate([c.sigma for c in moved])
    return PointCloud(points, colours, normals, sigma)


def view_index(clouds: Sequence[PointCloud]) -> np.ndarray:
    """(N,) uint16: for each point of :func:`merge_clouds` of ``clouds``, the index of the cloud it came from
    (merged.ply's ``view`` property)."""
    if len(clouds) > np.iinfo(np.uint16).max + 1:
        raise InputError(f"view_index: at most 65536 clouds fit a uint16 index, found {len(clouds)}")
    return np.repeat(np.arange(len(clouds), dtype=np.uint16), [len(c) for c in clouds])
