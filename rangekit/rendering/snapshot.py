"""Headless snapshots of meshes and point clouds as RGB uint8 images (reports, ``rangekit render``).

No display and no GPU: meshes are ray cast with Open3D's ``RaycastingScene``
(:mod:`rangekit.rendering.hits`: one scene per mesh, each camera's hits kept while the mesh lives, open3d
imported inside the functions that need it), clouds are splatted into a z-buffer with numpy. Frames and units follow
docs/ARCHITECTURE.md: world points in metres, OpenCV camera frame (x right, y down, z forward),
``T_world_cam`` maps camera to world, pixels ``(u, v) = (column, row)``; images are (H, W, 3) uint8 RGB.
"""

from __future__ import annotations

import base64
from typing import Callable, Sequence

import cv2
import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.colour import colourise
from rangekit.errors import InputError
from rangekit.geometry import apply_T, look_at
from rangekit.surface.mesh import TriangleMesh
from rangekit.rendering.hits import MESH_RENDER_BYTES_PER_PIXEL, MeshHits, raycast_mesh
from rangekit.surface.cloud import PointCloud

__all__ = ["MESH_RENDER_BYTES_PER_PIXEL", "CLOUD_RENDER_BYTES_PER_PIXEL",
           "fit_camera", "MeshHits", "raycast_mesh", "shade", "render_mesh", "render_cloud",
           "render_values_on_mesh", "colour_bar", "montage", "to_png_bytes", "data_uri"]

AMBIENT = 0.25
GREY = (0.75, 0.78, 0.82)
#: Peak memory of a cloud render per image pixel, bytes (measured, as MESH_RENDER_BYTES_PER_PIXEL), checked
#: against the memory budget (rangekit.budget) before it starts.
CLOUD_RENDER_BYTES_PER_PIXEL = 32


def _rgb255(colour, name: str, top: float = 255) -> np.ndarray:
    c = np.asarray(colour, dtype=np.float64).reshape(-1)
    if c.shape != (3,) or not np.all((c >= 0) & (c <= top)):
        raise InputError(f"{name}: expected an RGB triple in [0, {top:g}], found {colour!r}")
    return c


def _canvas(shape: tuple[int, int], background, where: str) -> np.ndarray:
    image = np.empty(shape + (3,), np.uint8)
    image[:] = _rgb255(background, f"{where} background").astype(np.uint8)
    return image


def fit_camera(points: np.ndarray, *, azimuth: float, elevation: float, size: tuple[int, int] = (640, 480),
               fov_deg: float = 30.0, up: Sequence[float] = (0.0, 0.0, 1.0), margin: float = 1.1,
               tight: bool = False) -> PinholeCamera:
    """A distortion-free camera looking at the centre of the bounding box of ``points`` from all around.

    Parameters
    ----------
    points : (N, 3) world points in metres, or (2, 3) bounds ``[min, max]``; non-finite rows are ignored.
    azimuth, elevation : radians. The camera sits in direction ``cos(el) (cos(az) e1 + sin(az) e2) +
        sin(el) up`` from the centre, with ``e1`` the world axis (x, or y if ``up`` is near x) made
        normal to ``up`` and ``e2 = up x e1`` (for ``up = z``: azimuth 0 looks from +x, pi/2 from +y).
    size : (width, height) in pixels.
    fov_deg : field of view across the smaller image side, degrees; square pixels, centred principal point.
    up : world direction that appears up in the image.
    margin : the bounding sphere of the box, scaled by ``margin``, just fits the smaller image side.
    tight : instead, move as close as the points allow (each inside the image with ``margin``; given
        bounds, the 8 box corners): the object fills more of the picture, and pictures from different
        sides differ in scale.

    Returns
    -------
    PinholeCamera with ``T_world_cam`` from :func:`rangekit.geometry.look_at`.
    """
    P = np.asarray(points, dtype=np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise InputError(f"fit_camera: expected (N, 3) points or (2, 3) bounds, found shape {P.shape}")
    if not np.isfinite(P).all():   # the copy only when needed: the report frames a 455k-vertex mesh 17 times
        P = P[np.all(np.isfinite(P), axis=1)]
    width, height = (int(s) for s in size)
    if len(P) == 0 or width <= 0 or height <= 0 or not 0 < fov_deg < 180 or not margin > 0:
        raise InputError(f"fit_camera: expected finite points, positive (width, height), 0 < fov_deg < 180 and "
                         f"margin > 0, found {len(P)} finite points, size {size}, fov {fov_deg}, margin {margin}")
    u = np.asarray(up, dtype=np.float64).reshape(3)
    if not abs(elevation) < np.pi / 2 - 1e-6 or not np.linalg.norm(u) > 0:
        raise InputError(f"fit_camera: expected elevation strictly inside (-pi/2, pi/2) radians and a non-zero "
                         f"'up' 3-vector, found elevation {elevation}, up {up!r}")
    u = u / np.linalg.norm(u)
    # Per column: numpy reduces an (N, 3) array along axis 0 several times slower than three strided columns.
    lo, hi = (np.array([f(P[:, k]) for k in range(3)]) for f in (np.min, np.max))
    # A single point (or all at one point) still gets a picture: a sphere of a millionth of its distance
    # from the origin (at least 1 micrometre) is framed instead.
    centre = (lo + hi) / 2
    radius = max(float(np.linalg.norm(hi - lo)) / 2, 1e-6 * max(1.0, float(np.abs(centre).max())))
    a = np.eye(3)[0] if abs(u[0]) < 0.9 else np.eye(3)[1]
    e1 = a - (a @ u) * u
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(u, e1)
    direction = np.cos(elevation) * (np.cos(azimuth) * e1 + np.sin(azimuth) * e2) + np.sin(elevation) * u
    half = np.radians(fov_deg) / 2
    distance = radius * margin / np.sin(half)  # the sphere's silhouette cone has half-angle asin(R / d)
    f = min(width, height) / 2 / np.tan(half)
    if tight:
        # Corner offsets in the look-at frame (towards the camera, image right, image up); a corner fits
        # when |lateral| / (d - toward) <= half image size / f, i.e. d >= toward + |lateral| f / half size.
        right = np.cross(direction, u)
        right /= np.linalg.norm(right)
        img_up = np.cross(right, direction)
        if len(P) > 8:  # the points themselves (a blob's box corners stick out far beyond its outline)
            corners = P[:: max(1, len(P) // 20_000)]
        else:
            corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        rel = corners - centre
        toward = rel @ direction
        need = np.maximum(np.abs(rel @ right) * margin * f / (width / 2), np.abs(rel @ img_up) * margin * f / (height / 2))
        distance = max(float(np.max(toward + need)), radius)  # never inside a point's own sphere
    K = np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1]])
    return PinholeCamera(K, width, height, np.zeros(5), look_at(centre + distance * direction, centre, u),
                         name="snapshot")


def shade(normal: np.ndarray, view_dir: np.ndarray, base_colour, *, ambient: float = AMBIENT) -> np.ndarray:
    """(..., 3) float64 RGB in [0, 1]: headlight Lambert ``base * (ambient + (1 - ambient) |n . v|)``.

    ``normal``, ``view_dir``: (..., 3) world unit vectors, ``view_dir`` from the camera to the surface; the
    light sits at the camera, so both faces are lit. ``base_colour``: (3,) or (..., 3) RGB in [0, 1].
    """
    lambert = np.abs(np.einsum("...i,...i->...", normal, view_dir))
    return np.asarray(base_colour, dtype=np.float64) * (ambient + (1 - ambient) * np.clip(lambert, 0, 1))[..., None]


def _to_uint8(rgb01: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(rgb01 * 255), 0, 255).astype(np.uint8)


def _view_dirs(points: np.ndarray, camera: PinholeCamera) -> np.ndarray:
    v = points - camera.center
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def render_mesh(mesh: TriangleMesh, camera: PinholeCamera, *, vertex_colours: np.ndarray | None = None,
                colour=GREY, background=(255, 255, 255), smooth: bool = False,
                colour_by_vertex: bool = True) -> np.ndarray:
    """(H, W, 3) uint8 RGB image of ``mesh``: headlight Lambert plus ambient, ``background`` where no hit.

    ``vertex_colours``: (V, 3) float in [0, 1] or uint8, interpolated with barycentrics; default the mesh's
    own ``vertex_colours`` if it has them, else the uniform ``colour`` (RGB in [0, 1]).
    ``smooth``: shade with interpolated vertex normals instead of face normals (dense scanned meshes).
    ``colour_by_vertex``: False ignores the mesh's own colours (``colour`` everywhere), e.g. to show shape
    without the noise of a scan's captured albedo.
    """
    hits = raycast_mesh(mesh, camera)
    normals = hits.smooth_normal if smooth else hits.normal
    vc = (mesh.vertex_colours if colour_by_vertex else None) if vertex_colours is None else vertex_colours
    m = hits.hit
    if vc is not None:
        vc = np.asarray(vc)
        if vc.shape != mesh.vertices.shape:
            raise InputError(f"render_mesh: vertex_colours must be {mesh.vertices.shape}, found {vc.shape}")
        vc = vc / 255.0 if vc.dtype == np.uint8 else vc.astype(np.float64)
        b = hits.bary[m]
        corners = vc[mesh.triangles[hits.triangle[m]]]  # (M, 3 corners, 3 channels)
        base = np.einsum("mk,mkc->mc", np.column_stack([1 - b.sum(axis=1), b]), corners)
    else:
        base = _rgb255(colour, "render_mesh colour", 1)
    image = _canvas(m.shape, background, "render_mesh")
    image[m] = _to_uint8(shade(normals[m], _view_dirs(hits.xyz[m], camera), base))
    return image


def render_cloud(cloud: PointCloud | np.ndarray, camera: PinholeCamera, *, values: np.ndarray | None = None,
                 vmin: float | None = None, vmax: float | None = None, cmap: str = "turbo", point_px: int = 1,
                 background=(255, 255, 255)) -> np.ndarray:
    """(H, W, 3) uint8 RGB image of a cloud: each point a flat square of side ``2 point_px + 1`` pixels.

    Z-buffer: the point nearest the camera (smallest camera-frame z) wins each pixel. Colour: ``values``
    (N,) through ``cmap`` over [vmin, vmax] (default their finite range), else the cloud's colours, else
    headlight shading of its normals, else uniform grey. ``cloud``: PointCloud or (N, 3) world points, metres.
    """
    pc = cloud if isinstance(cloud, PointCloud) else PointCloud(cloud)
    point_px = int(point_px)
    if point_px < 0:
        raise InputError(f"render_cloud: point_px must be a non-negative integer, found {point_px}")
    if values is not None:
        values = np.asarray(values, dtype=np.float64).reshape(-1)
        if values.shape != (len(pc),):
            raise InputError(f"render_cloud: values must be ({len(pc)},), one per point, found {values.shape}")
    H, W, r = camera.height, camera.width, point_px
    image = _canvas((H, W), background, "render_cloud")
    p_cam = apply_T(camera.T_cam_world, pc.points)
    z, uv = p_cam[:, 2], np.rint(camera.project_cam(p_cam))  # NaN behind the camera
    keep = np.flatnonzero(np.all(np.isfinite(uv), axis=1) & (uv[:, 0] >= -r) & (uv[:, 0] < W + r)
                          & (uv[:, 1] >= -r) & (uv[:, 1] < H + r))
    if keep.size == 0:
        return image
    # Points with the same centre pixel have the same footprint: only the nearest can win anywhere (ties:
    # the first point). Z-buffers by np.minimum.at instead of sorting: the same winners, a third of the CPU.
    cw = W + 2 * r
    centre = (uv[keep, 1].astype(np.int64) + r) * cw + (uv[keep, 0].astype(np.int64) + r)
    zk = z[keep]
    zbuf = np.full((H + 2 * r) * cw, np.inf)
    np.minimum.at(zbuf, centre, zk)
    near = np.flatnonzero(zk == zbuf[centre])
    first = np.full(zbuf.size, keep.size)
    np.minimum.at(first, centre[near], near)
    idx = keep[first[first < keep.size]]  # nearest point per centre pixel, by centre pixel
    idx = idx[np.argsort(z[idx], kind="stable")]  # near to far
    du, dv = (g.ravel() for g in np.meshgrid(np.arange(-r, r + 1), np.arange(-r, r + 1)))
    pu = uv[idx, 0].astype(np.int64)[:, None] + du
    pv = uv[idx, 1].astype(np.int64)[:, None] + dv
    inside = (pu >= 0) & (pu < W) & (pv >= 0) & (pv < H)
    # Each image pixel takes its nearest footprint: the lowest rank in the near-to-far order.
    rank = np.broadcast_to(np.arange(idx.size)[:, None], pu.shape)[inside]
    best = np.full(H * W, idx.size)
    np.minimum.at(best, pv[inside] * W + pu[inside], rank)
    pix = np.flatnonzero(best < idx.size)
    winners = idx[best[pix]]
    if values is not None:
        finite = values[np.isfinite(values)] if np.isfinite(values).any() else np.zeros(1)
        lo, hi = finite.min() if vmin is None else vmin, finite.max() if vmax is None else vmax
        rgb = colourise(values[winners], lo, hi, cmap=cmap)
    elif pc.colours is not None:
        rgb = _to_uint8(pc.colours[winners].astype(np.float64))
    elif pc.normals is not None:
        rgb = _to_uint8(shade(pc.normals[winners], _view_dirs(pc.points[winners], camera), GREY))
    else:
        rgb = _to_uint8(np.broadcast_to(np.asarray(GREY), (len(winners), 3)))
    image.reshape(-1, 3)[pix] = rgb
    return image


def render_values_on_mesh(mesh: TriangleMesh, camera: PinholeCamera,
                          value_fn: Callable[[np.ndarray], np.ndarray], *, vmin: float, vmax: float,
                          cmap: str = "turbo", background=(255, 255, 255),
                          smooth: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """A heat map of ``value_fn`` over the visible surface of ``mesh`` (e.g. distance to a true surface).

    ``value_fn`` maps (M, 3) world hit points (metres) to (M,) values; it is called once, on the hit points
    only. Colours from ``cmap`` over [vmin, vmax] are modulated by ``0.6 + 0.4 * lambert`` so the shape reads.

    Returns
    -------
    image : (H, W, 3) uint8 RGB, ``background`` where no hit.
    values : (H, W) float64, NaN off the mesh.
    """
    hits = raycast_mesh(mesh, camera)
    m = hits.hit
    pts = hits.xyz[m]
    vals = np.asarray(value_fn(pts), dtype=np.float64)
    if vals.shape != (len(pts),):
        raise InputError(f"render_values_on_mesh: value_fn must return ({len(pts)},) values for ({len(pts)}, 3) "
                         f"points, found shape {vals.shape}")
    values = np.full(m.shape, np.nan)
    values[m] = vals
    lambert = shade((hits.smooth_normal if smooth else hits.normal)[m], _view_dirs(pts, camera), np.ones(3),
                    ambient=0.0)
    image = _canvas(m.shape, background, "render_values_on_mesh")
    image[m] = _to_uint8(colourise(vals, vmin, vmax, cmap=cmap) / 255.0 * (0.6 + 0.4 * lambert))
    return image, values


def colour_bar(vmin: float, vmax: float, *, label: str, cmap: str = "turbo",
               size: tuple[int, int] = (320, 48)) -> np.ndarray:
    """(height, width, 3) uint8 RGB legend: the ``cmap`` ramp from vmin (left) to vmax (right), then the two
    limits and ``label`` (e.g. "error [mm]") in black on white. ``size`` is (width, height) in pixels."""
    width, height = (int(s) for s in size)
    if width < 16 or height < 24:
        raise InputError(f"colour_bar: size must be at least (16, 24) pixels (width, height), found {size}")
    img = np.full((height, width, 3), 255, np.uint8)
    pad, bar_h = 6, max(4, height // 2 - 6)
    img[4:4 + bar_h, pad:width - pad] = colourise(np.linspace(vmin, vmax, width - 2 * pad), vmin, vmax, cmap=cmap)
    font, scale, base = cv2.FONT_HERSHEY_SIMPLEX, min(0.4, height / 120), height - 6
    texts = [(f"{vmin:.3g}", "left"), (str(label), "centre"), (f"{vmax:.3g}", "right")]
    for text, where in texts:
        (tw, _), _ = cv2.getTextSize(text, font, scale, 1)
        x = {"left": pad, "centre": (width - tw) // 2, "right": width - pad - tw}[where]
        cv2.putText(img, text, (int(x), base), font, scale, (0, 0, 0), 1, cv2.LINE_AA)
    return img


def _check_image(image: np.ndarray, where: str) -> np.ndarray:
    img = np.asarray(image)
    if img.dtype != np.uint8 or not (img.ndim == 2 or (img.ndim == 3 and img.shape[2] == 3)):
        raise InputError(f"{where}: expected an (H, W) or (H, W, 3) uint8 image, found {img.dtype} {img.shape}")
    return img


def montage(images: Sequence[np.ndarray], cols: int, *, pad: int = 4, background: int = 255) -> np.ndarray:
    """Tile (H_i, W_i, 3) uint8 images row by row into a grid of ``cols`` columns, each centred in a cell the
    size of the largest image, ``pad`` pixels apart and around. Grey (H, W) images are expanded to RGB."""
    imgs = [_check_image(im, "montage") for im in images]
    if not imgs or int(cols) < 1 or int(pad) < 0:
        raise InputError(f"montage: expected at least one image, cols >= 1 and pad >= 0, found {len(imgs)} "
                         f"images, cols={cols}, pad={pad}")
    imgs = [np.repeat(im[:, :, None], 3, axis=2) if im.ndim == 2 else im for im in imgs]
    cols, pad = min(int(cols), len(imgs)), int(pad)
    rows = -(-len(imgs) // cols)
    ch, cw = max(im.shape[0] for im in imgs), max(im.shape[1] for im in imgs)
    out = np.full((rows * ch + (rows + 1) * pad, cols * cw + (cols + 1) * pad, 3), background, np.uint8)
    for k, im in enumerate(imgs):
        y = pad + (k // cols) * (ch + pad) + (ch - im.shape[0]) // 2
        x = pad + (k % cols) * (cw + pad) + (cw - im.shape[1]) // 2
        out[y:y + im.shape[0], x:x + im.shape[1]] = im
    return out


def to_png_bytes(image: np.ndarray) -> bytes:
    """Lossless PNG bytes of an (H, W) or (H, W, 3) uint8 RGB image (same encoding as ``io.write_png``)."""
    img = _check_image(image, "to_png_bytes")
    if img.ndim == 3:
        img = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2BGR)
    ok, buf = cv2.imencode(".png", img, [cv2.IMWRITE_PNG_COMPRESSION, 1])
    if not ok:
        raise InputError("to_png_bytes: OpenCV could not encode the image as PNG")
    return buf.tobytes()


def data_uri(image: np.ndarray) -> str:
    """``data:image/png;base64,...`` URI of a uint8 RGB image, for embedding in HTML."""
    return "data:image/png;base64," + base64.b64encode(to_png_bytes(image)).decode("ascii")
