"""A TSDF volume that depth maps are integrated into one at a time (Curless & Levoy 1996, Open3D's
``UniformTSDFVolume``): the batch fusion :func:`rangekit.surface.fusion.tsdf_fuse` and a scan's preview, fed
each view as it is decoded (:mod:`rangekit.app.scan.streaming`).

A view is ``(depth, colour, camera)``: ``depth`` (H, W) camera-frame z in metres (NaN or <= 0 where invalid),
``colour`` (H, W, 3) linear RGB in [0, 1] or None, ``camera`` a PinholeCamera of that size whose
``T_world_cam`` is the view's camera pose in the volume's frame. Units are metres.
"""

from __future__ import annotations

import numpy as np

from rangekit.camera import PinholeCamera
from rangekit.errors import InputError

__all__ = ["tsdf_volume", "integrate_view", "depth_image"]


def tsdf_volume(lo: np.ndarray, hi: np.ndarray, voxel: float, trunc: float, *, colour: bool,
                max_resolution: int = 384, what: str = "tsdf_fuse"):
    """An empty Open3D ``UniformTSDFVolume``: a cube of ``voxel`` metres voxels around the box ``lo``-``hi``
    (world, metres) plus the truncation band ``trunc`` and two voxels. InputError (naming ``what``) when the
    grid would need more than ``max_resolution`` voxels a side (Open3D takes 48 bytes a voxel: 384^3 is 2.7 GB).
    (``ScalableTSDFVolume`` integrates nothing in Open3D 0.20.)"""
    import open3d as o3d

    margin = trunc + 2 * voxel
    resolution = int(np.ceil((np.max(hi - lo) + 2 * margin) / voxel))
    if resolution > max_resolution:
        raise InputError(f"{what}: voxel_size {voxel:.4g} m needs a {resolution}^3 grid for a "
                         f"{np.max(hi - lo):.4g} m object; the limit is max_resolution={max_resolution}. Use a "
                         "larger voxel_size or raise max_resolution")
    length = resolution * voxel
    origin = (lo + hi) / 2 - length / 2
    colour_type = o3d.pipelines.integration.TSDFVolumeColorType
    return o3d.pipelines.integration.UniformTSDFVolume(
        length=length, resolution=resolution, sdf_trunc=trunc,
        color_type=colour_type.RGB8 if colour else colour_type.NoColor, origin=origin)


def integrate_view(volume, depth: np.ndarray, colour: np.ndarray | None, camera: PinholeCamera) -> None:
    """Integrate one view into ``volume`` (:func:`tsdf_volume`), resampled on the undistorted pinhole grid
    (:func:`depth_image`)."""
    import open3d as o3d

    z, rgb = depth_image(depth, colour, camera)
    if rgb is None:
        rgb = np.zeros(z.shape + (3,), np.uint8)
    rgbd = o3d.geometry.RGBDImage.create_from_color_and_depth(
        o3d.geometry.Image(rgb), o3d.geometry.Image(z), depth_scale=1.0, depth_trunc=1e9,
        convert_rgb_to_intensity=False)
    K = camera.K
    intrinsic = o3d.camera.PinholeCameraIntrinsic(camera.width, camera.height, K[0, 0], K[1, 1], K[0, 2], K[1, 2])
    volume.integrate(rgbd, intrinsic, camera.T_cam_world)


def depth_image(depth: np.ndarray, colour: np.ndarray | None, camera: PinholeCamera):
    """Resample a view's z-depth (metres, 0 = none) on the undistorted pinhole grid of ``camera``: ((H, W) float32,
    (H, W, 3) uint8 or None).

    Each pixel of the undistorted grid (same K, no distortion) takes the depth of the image pixel its
    ray crosses in the distorted image (nearest pixel). Unlike forward-projecting points into a
    z-buffer, this loses no pixel to rounding collisions when the points carry sub-pixel noise.
    """
    H, W = camera.height, camera.width
    K = camera.K
    grid = camera.pixel_grid()
    xy = np.column_stack([(grid[:, 0] - K[0, 2]) / K[0, 0], (grid[:, 1] - K[1, 2]) / K[1, 1]])
    src = np.rint(camera.normalized_to_pixels(xy))  # where each undistorted ray lands in the image
    inside = (src[:, 0] >= 0) & (src[:, 0] < W) & (src[:, 1] >= 0) & (src[:, 1] < H)
    src_idx = (src[inside, 1] * W + src[inside, 0]).astype(np.int64)
    z = depth.reshape(-1)[src_idx]
    out = np.zeros(H * W, np.float32)
    out[inside] = np.where(np.isfinite(z) & (z > 0), z, 0.0)
    rgb = None
    if colour is not None:
        c = np.asarray(colour, dtype=np.float32).reshape(-1, 3)
        rgb = np.zeros((H * W, 3), np.uint8)
        rgb[inside] = np.clip(np.rint(np.nan_to_num(c[src_idx]) * 255), 0, 255).astype(np.uint8)
        rgb = rgb.reshape(H, W, 3)
    return out.reshape(H, W), rgb
