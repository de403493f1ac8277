"""The names of ``rangekit.stereo``, each loaded from its module on first use (rangekit._runtime.lazy.attach_stub)."""

from .rectify import Rectification as Rectification, rectify as rectify, rectify_images as rectify_images
from .matching import (DisparityMap as DisparityMap, census_transform as census_transform,
    census_cost as census_cost, sgm_disparity as sgm_disparity, sgbm_disparity as sgbm_disparity)
from .pipeline import StereoResult as StereoResult, stereo_depth as stereo_depth
from .depth import (disparity_to_depth as disparity_to_depth, disparity_to_points as disparity_to_points,
    depth_in_camera as depth_in_camera)
from .dots import dots_depth as dots_depth, reference_disparity as reference_disparity
