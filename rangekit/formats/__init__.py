"""File formats and folders on disk: capture folders, poses.json, ToF capture folders, scan sessions
(session.json, summary.json)."""

from rangekit.formats.capture import (IMAGE_SUFFIXES, Capture, list_images, load_capture, pattern_spec_for,
                                      read_stack, save_decoded)
from rangekit.formats.poses import POSES_SCHEMA, load_poses, save_poses
from rangekit.formats.range_files import ToFFolder, load_ground_truth, load_tof_folder
from rangekit.formats.session import (SESSION_SCHEMA, CaptureSettings, ProcessResult, ScanPlan, Session,
                                      SessionView, SimulatorSettings, load_session, view_folder)

__all__ = ["IMAGE_SUFFIXES", "Capture", "list_images", "load_capture", "pattern_spec_for", "read_stack",
           "save_decoded", "POSES_SCHEMA", "load_poses", "save_poses", "ToFFolder", "load_ground_truth",
           "load_tof_folder", "SESSION_SCHEMA", "CaptureSettings", "ProcessResult",
           "ScanPlan", "Session", "SessionView", "SimulatorSettings", "load_session", "view_folder"]
