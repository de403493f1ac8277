"""Where a scan's error comes from, view by view, against the simulator's truth (issue 18, point 2).

For each view ``k`` (turntable angle ``a_k``) of a coded-light session:

- **decoding**: the decoded projector column against the true one (the projector column of the surface
  point each camera pixel sees, :func:`rangekit.sim.scene.raycast.cast_codes`), over the pixels where both
  exist: RMS and 95th percentile in projector pixels;
- **cloud**: each kept point's distance to the true surface posed at ``a_k`` (the view's own frame is the
  rig's world at ``a_k``): RMS, 95th percentile, max. Points are split by where they were seen: at a
  **depth edge** (within 2 pixels of a silhouette or a jump in the true depth, where a pixel mixes two
  surfaces) or **inside** a surface; ``edge_share`` is the edge points' share of the squared error, so
  filtering problems (mixed pixels, shadow borders) show apart from decoding noise;
- **registration**: the registered pose against the true turntable pose (rotation in degrees,
  translation of the object's centre in mm) and the RMS displacement it gives the view's points.

Frames: clouds in their view's frame; poses ``T_world_view`` with world = the first view's frame.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np
from scipy.ndimage import binary_dilation, maximum_filter, minimum_filter

from rangekit.camera import PinholeCamera, world_pixel_rays
from rangekit.formats.sessions.view_errors import (CloudErrors, DecodingErrors, DistanceStats, PoseErrors, ViewError,
                                                   ViewErrors)
from rangekit.geometry import apply_T, invert_T, rotation_angle
from rangekit.rig.rig_file import Rig
from rangekit.surface.mesh import TriangleMesh, distance_to_surface
from rangekit.sim.scene.raycast import cast_codes
from rangekit.sim.scene.passes import pass_scene, split_views, view_motions
from rangekit.sim.scene.scene import Scene

__all__ = ["view_errors", "view_surface_errors", "depth_edges"]

#: Pixels within this many of a depth edge count as edge pixels.
EDGE_PX = 2
#: A jump in true depth between neighbouring pixels larger than this share of the depth is an edge.
EDGE_JUMP = 0.01


def depth_edges(depth: np.ndarray, *, jump: float = EDGE_JUMP, radius: int = EDGE_PX) -> np.ndarray:
    """(H, W) bool: pixels within ``radius`` of a silhouette (hit next to no hit) or of a jump in ``depth``
    ((H, W) metres, NaN where nothing is hit) larger than ``jump`` times the depth."""
    d = np.where(np.isfinite(depth), depth, 0.0)
    hit = np.isfinite(depth)
    hi, lo = maximum_filter(d, size=3), minimum_filter(np.where(hit, d, np.inf), size=3)
    edge = hit & ((hi - lo) > jump * np.where(hit, d, 1.0))
    edge |= hit & binary_dilation(~hit)   # silhouette
    return binary_dilation(edge, iterations=radius)


#: Margin of the cast box around the cloud's pixels, pixels: wider than the edge radius.
_MARGIN = EDGE_PX + 3
#: How far :func:`depth_edges` looks from a pixel: its 3x3 filters, the silhouette's and the edge's dilations.
_EDGE_REACH = 2 + EDGE_PX


def _box(uv: np.ndarray, camera, margin: int) -> tuple[slice, slice] | None:
    """(rows, columns) slices of the pixel box around the cloud's pixels ``uv`` (N, 2) inside the image,
    ``margin`` pixels wider (clipped to the image); None when no point falls in the image."""
    H, W = camera.height, camera.width
    cols, rows = uv[:, 0], uv[:, 1]
    inside = (cols >= 0) & (cols < W) & (rows >= 0) & (rows < H)
    if not inside.any():
        return None
    return (slice(max(0, rows[inside].min() - margin), min(H, rows[inside].max() + margin + 1)),
            slice(max(0, cols[inside].min() - margin), min(W, cols[inside].max() + margin + 1)))


def _truth_in_box(world, camera: PinholeCamera, projector, box: tuple[slice, slice] | None,
                  cast: np.ndarray | None = None, light_at: np.ndarray | None = None):
    """``(geometry, edges)`` of the truth cast over the pixel ``box`` only (None: the whole image), both the
    box's size: :func:`rangekit.sim.scene.raycast.cast_codes` through a camera cropped to the box (the same K shifted
    by the box's corner, the same rays: sliced from the whole camera's), and :func:`depth_edges` of its depth
    with NaN around it, as if the whole image had been cast with nothing outside the box. The decoding
    errors leave out the object's pixels outside the box (its foot in the table band the cloud drops: 2 of
    186,034 pixels in one view of the 12-view scan, none in the others). Memory and rays scale with the box.

    ``cast``: the box's (h, w) bool pixels to cast (the others as if nothing were hit there; default all);
    ``light_at``: the box's (h, w) bool pixels whose hits on the object (object 0) the projector's light is traced
    for (``proj_col`` NaN elsewhere; default every hit). Each cast pixel's values are its own ray's, the same bits
    as in a whole cast; an edge is the whole cast's wherever every pixel within :data:`_EDGE_REACH` is cast."""
    if box is None:
        geometry = cast_codes(world, camera, projector)
        return geometry, depth_edges(geometry.depth)
    rows, cols = box
    h, w = rows.stop - rows.start, cols.stop - cols.start
    K = camera.K.copy()
    K[0, 2] -= cols.start
    K[1, 2] -= rows.start
    crop = PinholeCamera(K, w, h, camera.dist, camera.T_world_cam, name=camera.name)
    o, d = world_pixel_rays(camera)
    d_box = d.reshape(camera.height, camera.width, 3)[rows, cols].reshape(-1, 3)
    pixels = None if cast is None else np.flatnonzero(cast)
    geometry = cast_codes(world, crop, projector, cam_rays=(o[: h * w], d_box), pixels=pixels,
                          light_at=light_at, light_object=None if light_at is None else 0)
    return geometry, _box_edges(geometry.depth, box, camera)


def _needed(uv: np.ndarray, box: tuple[slice, slice], col_box: np.ndarray | None) -> tuple[np.ndarray, np.ndarray | None]:
    """``(cast, light_at)`` for :func:`_truth_in_box`: the box's pixels within :data:`_EDGE_REACH` of a cloud
    point's pixel (``uv`` (N, 2) columns, rows; the edges there are then the whole cast's) or decoded (``col_box``
    the box's decoded projector columns, NaN where undecoded, or None), and the decoded ones (None without
    ``col_box``): what the errors read, the same figures for 17% fewer camera rays and only the decoded
    object's light (the 12-view scan)."""
    rows, cols = box
    h, w = rows.stop - rows.start, cols.stop - cols.start
    u, v = uv[:, 0] - cols.start, uv[:, 1] - rows.start
    inside = (u >= 0) & (u < w) & (v >= 0) & (v < h)
    near = np.zeros((h, w), dtype=np.uint8)
    near[v[inside], u[inside]] = 1
    near = maximum_filter(near, size=2 * _EDGE_REACH + 1, mode="constant").astype(bool)
    if col_box is None:
        return near, None
    decoded = np.isfinite(col_box)
    return near | decoded, decoded


def _box_edges(depth_box: np.ndarray, box: tuple[slice, slice], camera) -> np.ndarray:
    """The box's part of :func:`depth_edges` of the whole image whose depth is ``depth_box`` inside ``box``
    and NaN (nothing hit) outside: the box padded with NaN by the edges' reach on every side that is not
    the image's border, filtered, the padding cut off."""
    rows, cols = box
    r = _EDGE_REACH
    pad = ((r if rows.start > 0 else 0, r if rows.stop < camera.height else 0),
           (r if cols.start > 0 else 0, r if cols.stop < camera.width else 0))
    edges = depth_edges(np.pad(depth_box, pad, constant_values=np.nan))
    return edges[pad[0][0]: edges.shape[0] - pad[0][1], pad[1][0]: edges.shape[1] - pad[1][1]]


def _stats(d: np.ndarray) -> DistanceStats:
    """RMS, 95th percentile and max of the distances ``d`` (metres)."""
    if d.size == 0:
        return DistanceStats(None, None, None, 0)
    return DistanceStats(float(np.sqrt(np.mean(d ** 2))), float(np.percentile(d, 95)), float(d.max()), int(d.size))


def view_errors(scene: Scene, rig: Rig, angles: Sequence[float], clouds: Sequence, T_world_view: np.ndarray,
                proj_cols: Sequence[np.ndarray] | None = None, names: Sequence[str] | None = None,
                pass_motions=None, measured: dict | None = None) -> ViewErrors:
    """One :class:`~rangekit.formats.sessions.view_errors.ViewError` per view (see the module docstring): ``decoding``
    (px), ``cloud`` (metres, with ``inside`` and ``edge`` parts and ``edge_share``), ``registration`` (radians,
    metres). ``clouds``: each view's PointCloud in
    its own frame; ``proj_cols``: each view's decoded (H, W) projector column (NaN where undecoded), or None
    to skip the decoding figure; ``scene``: the simulated scene (object first) at table angle 0. A multi-pass
    scan: ``pass_motions`` (P, 4, 4) and ``angles`` as ``(angle, pass)`` pairs (:mod:`rangekit.sim.scene.passes`);
    the true pose of each view then includes its pass's turn-over. ``measured``: view index -> what
    :func:`view_surface_errors` gave for that view (made while the scan ran), used instead of measuring again."""
    obj = scene.objects[0]
    motions = view_motions(rig, angles, pass_motions)
    T_true = np.stack([motions[0] @ invert_T(Mk) for Mk in motions])
    centre = obj.world_vertices().mean(axis=0)
    measured = measured or {}
    out = []
    for k, cloud in enumerate(clouds):
        col = None if proj_cols is None else proj_cols[k]
        surface = measured[k] if k in measured else view_surface_errors(scene, rig, angles, k, cloud, col,
                                                                         pass_motions)
        P = cloud.points
        E = invert_T(T_true[k]) @ T_world_view[k]
        c_view = apply_T(motions[k], centre[None])[0]   # the object's centre in view k's frame
        moved = np.linalg.norm(apply_T(E, P) - P, axis=1) if len(P) else np.zeros(0)
        registration = PoseErrors(float(rotation_angle(E[:3, :3])),
                                  float(np.linalg.norm(apply_T(E, c_view[None])[0] - c_view)),
                                  float(np.sqrt(np.mean(moved ** 2))) if moved.size else None)
        decoding, cloud_errors = surface
        out.append(ViewError(names[k] if names is not None else k, decoding, cloud_errors, registration))
    return ViewErrors(tuple(out))


def view_surface_errors(scene: Scene, rig: Rig, angles: Sequence[float], k: int, cloud,
                        proj_col: np.ndarray | None = None, pass_motions=None) -> tuple[DecodingErrors | None, CloudErrors]:
    """View ``k``'s errors that do not depend on its registered pose: ``(decoding, cloud)`` as in
    :func:`view_errors` (``angles`` and ``pass_motions`` as there: every view's, ``cloud`` and ``proj_col`` this
    view's). A scan's streaming processor measures each view with it as the view is decoded."""
    obj = scene.objects[0]
    motions = view_motions(rig, angles, pass_motions)
    angle_k, passes, F = split_views(angles, pass_motions)
    p = int(passes[k])
    view_scene = scene if p == 0 else pass_scene(scene, F[p])
    camera = rig.camera
    truth = TriangleMesh(apply_T(motions[k], obj.world_vertices()), obj.triangles)
    P = cloud.points
    d = distance_to_surface(P, truth) if len(P) else np.zeros(0)
    uv = np.rint(camera.project(P)).astype(np.int64) if len(P) else np.zeros((0, 2), np.int64)
    box = _box(uv, camera, _MARGIN)
    cast, light_at = (None, None) if box is None else _needed(uv, box, None if proj_col is None else proj_col[box])
    geometry, edges = _truth_in_box(view_scene.world_mesh(rig.T_world_rotated(float(angle_k[k]))), camera,
                                    rig.projector if box is None or proj_col is not None else None, box, cast,
                                    light_at)
    r0, c0 = (box[0].start, box[1].start) if box is not None else (0, 0)
    H, W = edges.shape
    u, v = uv[:, 0] - c0, uv[:, 1] - r0
    inside_img = (u >= 0) & (u < W) & (v >= 0) & (v < H)
    edge = np.zeros(len(P), dtype=bool)
    edge[inside_img] = edges[v[inside_img], u[inside_img]]
    sq = float(np.sum(d ** 2))
    cloud_stats = CloudErrors(_stats(d), _stats(d[~edge]), _stats(d[edge]),
                              float(np.sum(d[edge] ** 2) / sq) if sq > 0 else 0.0)
    decoding = None
    if proj_col is not None:
        col = proj_col if box is None else proj_col[box]
        both = np.isfinite(col) & np.isfinite(geometry.proj_col) & (geometry.object_id == 0)
        e = (col - geometry.proj_col)[both]
        decoding = DecodingErrors(float(np.sqrt(np.mean(e ** 2))) if e.size else None,
                                  float(np.percentile(np.abs(e), 95)) if e.size else None, int(e.size))
    del geometry, edges     # its pages serve the next view's cast (processing: reuse_freed_memory)
    return decoding, cloud_stats
