"""Other tools' capture folders as data (issue 35): :data:`LAYOUTS`, every preset by name, and the machinery of
:mod:`rangekit.formats.layouts.layout`. One module per tool holds that tool's presets."""

from rangekit.formats.layouts.layout import (BLACK_FROM_PAIRS, BLACK_FROM_STEPS, WHITE_FROM_PAIRS, WHITE_FROM_STEPS,
                                             AxisBlocks, CaptureLayout, Inverse,
                                             arrange, decoding_projector, from_decoding_projector, in_projector_pixels,
                                             layout_files,
                                             tool_frames)
from rangekit.formats.layouts.opencv import OPENCV_LAYOUTS, read_image_list
from rangekit.formats.layouts.frame_files import FrameFiles, capture_frames, folder_frames
from rangekit.formats.layouts.procam import PROCAM_LAYOUTS
from rangekit.formats.layouts.roomalive import ROOMALIVE_LAYOUTS
from rangekit.formats.layouts.scan3d import SCAN3D_LAYOUTS
from rangekit.formats.layouts.slstudio import SLSTUDIO_LAYOUTS

__all__ = ["LAYOUTS", "AxisBlocks", "CaptureLayout", "FrameFiles", "capture_frames", "folder_frames", "Inverse",
           "WHITE_FROM_STEPS", "BLACK_FROM_STEPS", "WHITE_FROM_PAIRS", "BLACK_FROM_PAIRS", "arrange",
           "decoding_projector", "from_decoding_projector", "in_projector_pixels", "layout_files", "read_image_list", "tool_frames"]

#: Every preset by its name ("tool:codec").
LAYOUTS = {**SLSTUDIO_LAYOUTS, **OPENCV_LAYOUTS, **PROCAM_LAYOUTS, **SCAN3D_LAYOUTS, **ROOMALIVE_LAYOUTS}
