"""Free-space carving on the turntable (Fusiello 17.2.1 shape from silhouette, 17.2.4 space carving): what the
views saw as empty, as a voxel volume, and a closed mesh held out of it.

Every decoded camera pixel saw light come back from a surface (the object or the turntable) at a known depth:
its ray is empty from the camera up to that depth. A pixel lit and off the object (on the turntable) carves
the whole ray down to the table, which is the shape from silhouette; a pixel on the object carves in front of
the surface, which reaches into concavities a silhouette cannot. The turntable is solid: nothing of the object
lies below its top. What is neither carved nor under the table is the *hull*: the object and whatever no view
could see into (under an overhang near the table no ray reaches; the projector's light paths, each decoded
point lit along its projector ray, were tried as more views and carved nothing more on the default object).

- :func:`free_depth`: a view's (H, W) depth up to which each pixel's ray is empty (0 where unknown).
- :func:`carve`: the :class:`CarvedSpace` of several views on a voxel grid in the table's frame.
- :func:`hold_out`: a closed mesh's unobserved vertices moved out of carved space onto the hull, and which
  vertices lie on the hull (``carved``).
- :func:`fill_in_hull`: a closed mesh's free vertices placed where the surface bends least (the thin-plate energy,
  :func:`rangekit.surface.thin_plate.thin_plate_band`) on or above the table top and outside carved space.
- :func:`close_in_hull`: the unobserved vertices and the observed rim's :data:`RIM_RINGS` rings around them
  filled so, then held out: what ``rangekit process`` does.

Units are metres; the views' cameras and the mesh share one frame ("world"); the grid lives in the table frame
(``T_world_table``: z up from the table top). Deterministic: numpy, scipy and one numba kernel (each voxel against
each view, the lens model's own compiled distortion: 0.33 CPU-s for 12 views of the default object, 2.7 in numpy).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

from rangekit._compiled.lens import distort_point
from rangekit.camera import PinholeCamera
from rangekit.errors import InputError
from rangekit.geometry import apply_T, invert_T

__all__ = ["CARVE_MARGIN", "GRID_VOXELS", "TABLE_COLUMNS", "TableView", "table_view", "view_depth",
           "CarvedSpace", "free_depth", "carve", "hold_out", "close_in_hull", "fill_in_hull", "RIM_RINGS",
           "HULL_PASSES"]

#: Metres: a voxel is carved when its centre lies this far in front of the depth a view measured along the
#: pixel's ray: 20x the views' noise (0.015 mm RMS on the default object), so no noise carves the surface. The
#: hull's boundary then lies within half a voxel of the surface the views measured. A margin of one voxel
#: (1.3 mm) left the lowest layer over the table uncarved everywhere (a view looking down at 30 degrees sees a
#: centre 0.65 mm above the table only 1.2 mm in front of it): the closed mesh's floor spread 6 mm wide there.
CARVE_MARGIN = 0.0003
#: Voxels along the grid's longest side by default.
GRID_VOXELS = 160
#: A decoded pixel off the object sees the table top when its projector column is within this many columns of
#: the one the table top would show it (the decoding's error is a small fraction of a column).
TABLE_COLUMNS = 1.0
#: Rings of observed vertices around each hole that :func:`close_in_hull` fills in again with the hole: where
#: Poisson's surface bends towards its guess (normals 25, 19, 9 and 4 degrees off the truth at the 90th percentile
#: on the bowl's first four rings, under 2 from the fifth on; 9, 6, 3 and 2.5 on lumpy's; docs/benchmarks.md).
RIM_RINGS = 4
#: Passes of :func:`fill_in_hull` that hold the vertices inside carved space on the hull and solve the rest again.
HULL_PASSES = 3
_TABLE_PASSES = 8  # active-set passes of the table top (each adds the vertices still under it; 1-2 are used)
_CHUNK = 1 << 19   # voxels tested at a time (each view)


@dataclass(frozen=True, eq=False)
class TableView:
    """What a fixed camera and projector see of the (rotating, so unchanging) table top, per camera pixel:
    ``depth`` (H, W) camera-frame z of the table plane along each pixel's ray, and ``proj_col`` (H, W) the
    projector column lighting that table point; NaN where the ray misses the plane (or the projector)."""

    depth: np.ndarray
    proj_col: np.ndarray


def table_view(camera: PinholeCamera, projector: PinholeCamera, T_world_table: np.ndarray) -> TableView:
    """The :class:`TableView` of ``camera`` and ``projector`` (rig world) on the table plane (z = 0 of
    ``T_world_table``): computed once for a turntable scan, whose views all see the same plane; one compiled pass
    over the camera's cached pixel rays (0.9 CPU-s in numpy for 1280 x 1024, the projection's temporaries)."""
    from rangekit.camera import pixel_rays
    from rangekit.lens import _full_coeffs

    d = np.ascontiguousarray(pixel_rays(camera).reshape(-1, 3), dtype=np.float64)      # camera frame
    T_cam_table = camera.T_cam_world @ np.asarray(T_world_table, np.float64)
    n, p0 = T_cam_table[:3, 2], T_cam_table[:3, 3]             # the plane's normal and a point, camera frame
    A = (projector.T_cam_world @ camera.T_world_cam)[:3]       # projector from camera
    depth, col = np.empty(len(d)), np.empty(len(d))
    _table_kernel(d, np.ascontiguousarray(n), float(p0 @ n), np.ascontiguousarray(A),
                  np.asarray(projector.K, np.float64), _full_coeffs(np.asarray(projector.dist, np.float64)), depth, col)
    shape = (camera.height, camera.width)
    return TableView(depth.reshape(shape), col.reshape(shape))


@njit(cache=True, nogil=True)
def _table_kernel(d, n, c, A, K, dist, depth, col):  # pragma: no cover - compiled
    """:func:`table_view` per pixel ray ``d[i]`` (camera frame): its hit on the plane ``x . n = c``, that point's
    camera z and its projector column (the lens model's own distortion); NaN where the ray misses the plane
    or the point lies behind the projector."""
    for i in range(len(d)):
        t = c / (d[i, 0] * n[0] + d[i, 1] * n[1] + d[i, 2] * n[2])
        depth[i] = np.nan
        col[i] = np.nan
        if not (t > 0 and np.isfinite(t)):
            continue
        x, y, z = d[i, 0] * t, d[i, 1] * t, d[i, 2] * t
        depth[i] = z
        zp = A[2, 0] * x + A[2, 1] * y + A[2, 2] * z + A[2, 3]
        if zp > 0:
            xd, _ = distort_point((A[0, 0] * x + A[0, 1] * y + A[0, 2] * z + A[0, 3]) / zp,
                                  (A[1, 0] * x + A[1, 1] * y + A[1, 2] * z + A[1, 3]) / zp, dist)
            col[i] = K[0, 0] * xd + K[0, 2]


def view_depth(depth: np.ndarray, proj_col: np.ndarray, table: TableView) -> np.ndarray:
    """(H, W) camera-frame z of the surface each decoded pixel of a view saw: ``depth`` (H, W) where the view
    kept a point of the object, else the table top's where the decoded ``proj_col`` (H, W, NaN undecoded or
    weak) is the table's own (:data:`TABLE_COLUMNS`); NaN elsewhere (undecoded, or a dropped point of the
    object: its depth unknown)."""
    with np.errstate(invalid="ignore"):
        on_table = np.abs(np.asarray(proj_col) - table.proj_col) <= TABLE_COLUMNS
    return np.where(np.isfinite(depth), depth, np.where(on_table, table.depth, np.nan))


def free_depth(depth: np.ndarray, *, erode: int = 1) -> np.ndarray:
    """(H, W) float32 metres: camera-frame z up to which each pixel's ray is empty, from ``depth`` (H, W) the
    camera-frame z of the surface each decoded pixel saw (object or turntable), NaN or <= 0 where nothing was
    decoded. 0 where unknown. Each pixel takes the least depth of its ``(2 erode + 1)^2`` neighbourhood, so a
    pixel at a silhouette (a ray passing the object's edge) does not carve the edge it grazes."""
    from scipy.ndimage import minimum_filter

    D = np.asarray(depth, dtype=np.float32)
    if D.ndim != 2:
        raise InputError(f"free_depth: depth must be (H, W), found shape {D.shape}")
    D = np.where(np.isfinite(D) & (D > 0), D, 0.0).astype(np.float32)
    return minimum_filter(D, size=2 * int(erode) + 1, mode="constant", cval=0.0) if erode > 0 else D


@dataclass(frozen=True, eq=False)
class CarvedSpace:
    """What the views saw as empty, on a voxel grid in the table frame.

    T_world_table : (4, 4) the table frame (z up from the table top) in the world.
    origin : (3,) table-frame centre of voxel (0, 0, 0), metres; the grid's lowest voxels lie under the table.
    voxel : metres, the grid's step.
    carved : (X, Y, Z) bool: some view saw the voxel's centre empty, or it lies under the table top.
    """

    T_world_table: np.ndarray
    origin: np.ndarray
    voxel: float
    carved: np.ndarray

    def centres(self, index: np.ndarray) -> np.ndarray:
        """(N, 3) world centres of the voxels of ``index`` (N, 3) int."""
        return apply_T(self.T_world_table, self.origin + np.asarray(index, dtype=np.float64) * self.voxel)

    def _grid(self, points: np.ndarray) -> np.ndarray:
        return ((apply_T(invert_T(self.T_world_table), np.asarray(points, np.float64)) - self.origin)
                / self.voxel)

    def is_carved(self, points: np.ndarray) -> np.ndarray:
        """(N,) bool: the voxel holding each world point (N, 3) is carved (False outside the grid)."""
        g = np.rint(self._grid(points)).astype(np.int64)
        inside = np.all((g >= 0) & (g < np.array(self.carved.shape)), axis=1)
        out = np.zeros(len(g), dtype=bool)
        out[inside] = self.carved[tuple(g[inside].T)]
        return out

    def depth_inside(self, points: np.ndarray) -> np.ndarray:
        """(N,) metres: how far each world point (N, 3) lies inside carved space (its distance to the hull,
        trilinear between voxel centres), negative inside the hull (minus its distance to carved space)."""
        from scipy.ndimage import map_coordinates

        return map_coordinates(self._field, self._grid(points).T, order=1, mode="nearest")

    @property
    def _field(self) -> np.ndarray:
        f = self.__dict__.get("_sdf")
        if f is None:
            from scipy.ndimage import distance_transform_edt

            c = self.carved
            # voxel-centre distances to the other class, shifted half a voxel: zero on the boundary between them
            f = np.where(c, distance_transform_edt(c) - 0.5, -(distance_transform_edt(~c) - 0.5)) * self.voxel
            object.__setattr__(self, "_sdf", f.astype(np.float32))
            f = self.__dict__["_sdf"]
        return f


def carve(views: Sequence[tuple[np.ndarray, PinholeCamera]], T_world_table: np.ndarray, lo: np.ndarray,
          hi: np.ndarray, *, voxel: float | None = None, margin: float = CARVE_MARGIN) -> CarvedSpace:
    """Carve a grid spanning ``lo`` .. ``hi`` (3,) metres in the table frame (``lo[2]`` is not used: the grid
    starts two voxels under the table top) by every view of ``views``: ``(free, camera)``, ``free`` the
    view's :func:`free_depth` (H, W) and ``camera`` posed where it saw the object from (world frame). A voxel is
    carved when some view sees its centre in front of that pixel's free depth by ``margin`` metres, or
    when it lies under the table top. ``voxel`` metres: default the longest side over :data:`GRID_VOXELS`."""
    lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
    if lo.shape != (3,) or hi.shape != (3,) or not np.all(hi > lo):
        raise InputError(f"carve: lo and hi must be (3,) with hi > lo, found {lo} and {hi}")
    h = float(voxel) if voxel is not None else float(np.max(hi - lo)) / GRID_VOXELS
    if not h > 0:
        raise InputError(f"carve: voxel must be > 0 metres, found {voxel!r}")
    lo = np.array([lo[0], lo[1], -1.5 * h])
    shape = tuple(int(n) for n in np.ceil((hi - lo) / h).astype(np.int64) + 1)
    carved = np.zeros(shape, dtype=bool)
    carved[:, :, :2] = True          # centres at -1.5 h and -0.5 h: under the table top
    space = CarvedSpace(np.asarray(T_world_table, np.float64), lo, h, carved)
    flat = carved.reshape(-1)
    cams = [(np.ascontiguousarray(free, dtype=np.float32), camera) for free, camera in views]
    for start in range(0, flat.size, _CHUNK):
        idx = np.arange(start, min(start + _CHUNK, flat.size))
        idx = idx[~flat[idx]]
        for free, camera in cams:
            if not len(idx):
                break
            hit = _seen_empty(free, camera, space, idx, margin)
            flat[idx[hit]] = True
            idx = idx[~hit]
    return space


def _seen_empty(free: np.ndarray, camera: PinholeCamera, space: CarvedSpace, idx: np.ndarray,
                margin: float) -> np.ndarray:
    """(N,) bool: the centres of the voxels ``idx`` (N,) (flat indices of ``space``'s grid) lie in front of
    ``free`` (the view's :func:`free_depth`, float32) by ``margin``, each projected as ``camera.project`` does
    (the lens model's own compiled :func:`rangekit._compiled.lens.distort_point`), in one compiled pass."""
    from rangekit.lens import _full_coeffs

    A = (camera.T_cam_world @ space.T_world_table)[:3]          # camera from table: the grid's own frame
    out = np.empty(len(idx), dtype=np.bool_)
    _seen_empty_kernel(np.ascontiguousarray(idx, np.int64), np.array(space.carved.shape, np.int64),
                       np.asarray(space.origin, np.float64), float(space.voxel), np.ascontiguousarray(A),
                       np.asarray(camera.K, np.float64), _full_coeffs(np.asarray(camera.dist, np.float64)), free,
                       float(margin), out)
    return out


@njit(cache=True, nogil=True)
def _seen_empty_kernel(idx, shape, origin, h, A, K, d, free, margin, out):  # pragma: no cover - compiled
    """:func:`_seen_empty`: each voxel's table-frame centre to the camera, distorted, its nearest pixel's test."""
    H, W = free.shape
    for n in range(len(idx)):
        i = idx[n]
        iz = i % shape[2]
        iy = (i // shape[2]) % shape[1]
        ix = i // (shape[2] * shape[1])
        x = origin[0] + ix * h
        y = origin[1] + iy * h
        z = origin[2] + iz * h
        zc = A[2, 0] * x + A[2, 1] * y + A[2, 2] * z + A[2, 3]
        out[n] = False
        if not zc > 0:
            continue
        xd, yd = distort_point((A[0, 0] * x + A[0, 1] * y + A[0, 2] * z + A[0, 3]) / zc,
                               (A[1, 0] * x + A[1, 1] * y + A[1, 2] * z + A[1, 3]) / zc, d)
        u = np.rint(K[0, 0] * xd + K[0, 2])
        v = np.rint(K[1, 1] * yd + K[1, 2])
        if 0 <= u < W and 0 <= v < H:
            out[n] = zc < free[int(v), int(u)] - margin


def hold_out(vertices: np.ndarray, movable: np.ndarray, space: CarvedSpace, *,
             iterations: int = 6, reach: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices, on_hull)``: the ``movable`` (V,) bool ones of ``vertices`` (V, 3, world) that lie in carved
    space moved onto the hull (Newton steps along the gradient of :meth:`CarvedSpace.depth_inside`), the others
    as given; ``on_hull`` (V,) bool: movable vertices now within one voxel of the hull's surface (the hull, not a
    fitted guess, gives their place)."""
    V = np.array(vertices, dtype=np.float64)
    movable = np.asarray(movable, dtype=bool)
    if V.ndim != 2 or V.shape[1] != 3 or movable.shape != (len(V),):
        raise InputError(f"hold_out: vertices must be (V, 3) and movable (V,), found {V.shape} and {movable.shape}")
    h = space.voxel
    idx = np.flatnonzero(movable)
    # under the table top (beyond the grid's floor, where its field has no slope): onto the table first
    T_table_world = invert_T(space.T_world_table)
    P = apply_T(T_table_world, V[idx])
    P[:, 2] = np.maximum(P[:, 2], 0.0)
    V[idx] = apply_T(space.T_world_table, P)
    for _ in range(iterations):
        d = space.depth_inside(V[idx])
        out = (d > 0.05 * h) | ((d < -0.05 * h) & (d >= -reach))
        if not out.any():
            break
        idx_o, P, d = idx[out], V[idx[out]], d[out]
        g = np.column_stack([(space.depth_inside(P + e) - space.depth_inside(P - e)) / h
                             for e in np.eye(3) * (0.5 * h)])
        n = np.linalg.norm(g, axis=1)
        g = np.where(n[:, None] > 1e-9, g / np.maximum(n, 1e-9)[:, None], 0.0)
        V[idx_o] = P - d[:, None] * g
    d = space.depth_inside(V)
    on_hull = movable & (np.abs(d) <= h)
    return V, on_hull



def close_in_hull(vertices: np.ndarray, triangles: np.ndarray, movable: np.ndarray,
                  space: CarvedSpace) -> tuple[np.ndarray, np.ndarray]:
    """``(vertices, on_hull)``: the closed mesh ``vertices`` (V, 3, world), ``triangles`` (F, 3) with its
    ``movable`` (V,) bool (unobserved) vertices filled in by :func:`fill_in_hull` and held out of carved space
    (:func:`hold_out`); ``on_hull`` (V,) bool: movable vertices within a voxel of the hull (and the observed ones held out, below). The fill also re-places
    the :data:`RIM_RINGS` rings of observed vertices around each hole: Poisson's surface bends towards its own
    guess there (its normals up to 25 degrees off on the bowl's rim ring, within 2 degrees from the fifth ring on;
    docs/benchmarks.md), and a fill continues the slope it is given. A connected part of the filled vertices that
    the fill leaves off the grid or more than a voxel inside carved space is held out from where it was given
    instead. An observed vertex more than a voxel inside carved space (a view saw through where it lies: the
    48-frame thin object's 28 vertices up to 1.35 voxels deep, 0.66-0.98 mm off the truth) is held out onto the
    hull too, and counted ``on_hull``: the hull, not the points, gives its place."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    from rangekit.surface.thin_plate import ring_band

    F = np.asarray(triangles, np.int64)
    movable = np.asarray(movable, dtype=bool)
    given, given_on = hold_out(vertices, movable, space)
    wide = ring_band(F, movable, RIM_RINGS) if movable.any() and not movable.all() else movable
    V, on_hull = hold_out(fill_in_hull(vertices, F, wide, space), wide, space)
    on_hull &= movable
    g = space._grid(V)
    bad = wide & ((space.depth_inside(V) > space.voxel)
                  | np.any((g < -0.5) | (g > np.array(space.carved.shape) - 0.5), axis=1))
    if bad.any():
        e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
        e = e[wide[e[:, 0]] & wide[e[:, 1]]]
        n = len(wide)
        _, part = connected_components(coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n)), directed=False)
        back = wide & np.isin(part, np.unique(part[bad]))
        V[back], on_hull[back] = given[back], given_on[back]
    seen_through = ~movable & (space.depth_inside(V) > space.voxel)
    if seen_through.any():
        V, held = hold_out(V, seen_through, space)
        on_hull |= held
    return V, on_hull


def fill_in_hull(vertices: np.ndarray, triangles: np.ndarray, free: np.ndarray, space: CarvedSpace, *,
                 passes: int = HULL_PASSES) -> np.ndarray:
    """(V, 3) ``vertices`` (world) with the ``free`` (V,) bool ones placed where they bend least
    (:func:`rangekit.surface.thin_plate.thin_plate_band`: the fixed surface's position and slope continued) on or
    above the table top and outside carved space. In the table frame: x and y free, z solved with the vertices
    that would go under the table held on it (an active set: each pass adds those still under it); then, for
    ``passes`` passes, the vertices more than half a voxel inside carved space are held out onto the hull
    (:func:`hold_out`), held there, and the rest solved again, so the fill bends smoothly off the hull where it
    touches it instead of being pushed onto it vertex by vertex."""
    from rangekit.surface.thin_plate import thin_plate_band

    V = np.array(vertices, dtype=np.float64)
    free = np.asarray(free, dtype=bool)
    if V.ndim != 2 or V.shape[1] != 3 or free.shape != (len(V),):
        raise InputError(f"fill_in_hull: vertices must be (V, 3) and free (V,), found {V.shape} and {free.shape}")
    if not free.any() or free.all():
        return V
    T_table_world = invert_T(space.T_world_table)
    band = thin_plate_band(apply_T(T_table_world, V), triangles, free)
    X = apply_T(T_table_world, V[band.used])
    held = np.zeros(len(X), dtype=bool)           # held out onto the hull: fixed in all three coordinates
    for p in range(passes + 1):
        fr = band.free & ~held
        X[:, :2] = band.solve(X[:, :2], fr)
        on_table = np.zeros(len(X), dtype=bool)
        for _ in range(_TABLE_PASSES):
            z = band.solve(np.where(on_table, 0.0, X[:, 2]), fr & ~on_table)
            under = fr & ~on_table & (z < 0)
            X[:, 2] = z
            if not under.any():
                break
            on_table |= under
        X[on_table, 2] = 0.0
        if p == passes:
            break
        W = apply_T(space.T_world_table, X)
        inside = fr & (space.depth_inside(W) > 0.5 * space.voxel)
        if not inside.any():
            break
        out = np.zeros(len(V), dtype=bool)
        out[band.used[inside]] = True
        moved = V.copy()
        moved[band.used] = W
        moved, _ = hold_out(moved, out, space)
        X[inside] = apply_T(T_table_world, moved[band.used[inside]])
        held |= inside
    V[band.used[band.free]] = apply_T(space.T_world_table, X[band.free])
    return V
