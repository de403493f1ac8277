"""The names of ``rangekit.formats.layouts``, each loaded from its module on first use (rangekit._runtime.lazy.attach_stub)."""

from .layout import (AxisBlocks as AxisBlocks, CaptureLayout as CaptureLayout, Inverse as Inverse,
    WHITE_FROM_STEPS as WHITE_FROM_STEPS, BLACK_FROM_STEPS as BLACK_FROM_STEPS,
    WHITE_FROM_PAIRS as WHITE_FROM_PAIRS, BLACK_FROM_PAIRS as BLACK_FROM_PAIRS, arrange as arrange,
    decoding_projector as decoding_projector, from_decoding_projector as from_decoding_projector,
    in_projector_pixels as in_projector_pixels, layout_files as layout_files, tool_frames as tool_frames)
from .frame_files import FrameFiles as FrameFiles, capture_frames as capture_frames, folder_frames as folder_frames
from .opencv import read_image_list as read_image_list
