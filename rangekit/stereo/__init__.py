"""Active stereo: rectification, census + semi-global matching, disparity to depth (Fusiello ch. 12, 13.2.1).

The pipeline (:func:`stereo_depth`):

1. **Rectify** (:func:`rectify`, Fusiello 12.5): rotate both cameras about their centres so that their image
   planes coincide and rows are epipolar lines (``cv2.stereoRectify``, zero-disparity principal points),
   undistort and resample both images (:func:`rectify_images`). A point at depth z (rectified-left frame)
   then appears at the same row in both images, ``d = u_left - u_right = f B / z`` pixels apart.
2. **Match** (:func:`sgm_disparity`): census transform (bit string of "neighbour darker than centre" over a
   window, Zabih & Woodfill 1994), Hamming matching cost, semi-global aggregation along 4 or 8 paths
   (Hirschmuller 2008)::

       L_r(p, d) = C(p, d) + min(L_r(p - r, d), L_r(p - r, d +- 1) + P1, min_k L_r(p - r, k) + P2)
                   - min_k L_r(p - r, k)

   summed over the paths, winner-take-all, uniqueness test, left-right consistency check (Fusiello
   12.6.2: the right image's best match must point back), sub-pixel fit on the aggregated cost, optional
   3 x 3 median. :func:`sgbm_disparity` runs OpenCV's StereoSGBM instead, with the same output.
3. **Triangulate** (:func:`disparity_to_depth`, :func:`disparity_to_points`, :func:`depth_in_camera`):
   z = f B / d, and back to the original (distorted) left camera's pixel grid.

Frames: the rectified-left frame is the left camera frame rotated by ``R1`` (``X_rect = R1 @ X_left``),
origin at the left centre. Disparities are in rectified pixels, depths in metres.
"""

from rangekit.stereo.depth import depth_in_camera, disparity_to_depth, disparity_to_points
from rangekit.stereo.dots import dots_depth, reference_disparity
from rangekit.stereo.matching import DisparityMap, census_cost, census_transform, sgbm_disparity, sgm_disparity
from rangekit.stereo.pipeline import StereoResult, stereo_depth
from rangekit.stereo.rectify import Rectification, rectify, rectify_images

__all__ = ["Rectification", "DisparityMap", "StereoResult", "rectify", "rectify_images", "census_transform",
           "census_cost", "sgm_disparity", "sgbm_disparity", "disparity_to_depth", "disparity_to_points",
           "depth_in_camera", "stereo_depth", "dots_depth", "reference_disparity"]
