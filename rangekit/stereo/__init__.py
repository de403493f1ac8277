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

from rangekit._runtime.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
