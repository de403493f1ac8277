"""Files a user keeps: point clouds (PLY, PCD, XYZ, NPY) and meshes (PLY, OBJ, STL) with one PLY reader and
writer, capture folders, poses.json, ToF capture folders, scan sessions (session.json, summary.json)."""

from rangekit.formats.capture import (IMAGE_SUFFIXES, Capture, list_images, load_capture, pattern_spec_for,
                                      read_stack, save_decoded)
from rangekit.formats.clouds import CLOUD_READERS, CLOUD_WRITERS, RangeGrid, load_cloud, load_range_grid, save_cloud
from rangekit.formats.meshes import MESH_FORMATS, load_mesh_file, save_mesh
from rangekit.formats.ply import cloud_ply_bytes, mesh_ply_bytes, read_ply
from rangekit.formats.poses import POSES_SCHEMA, load_poses, save_poses
from rangekit.formats.range_files import ToFFolder, load_ground_truth, load_tof_folder
from rangekit.formats.session import (SESSION_SCHEMA, CaptureSettings, ScanPlan, Session, SessionView,
                                      SimulatorSettings, load_session, view_folder)
from rangekit.formats.session_check import verify_views
from rangekit.formats.session_lock import SessionLocked, session_lock
from rangekit.formats.summary import SUMMARY_SCHEMA, ProcessResult

__all__ = ["load_cloud", "save_cloud", "CLOUD_READERS", "CLOUD_WRITERS", "RangeGrid", "load_range_grid",
           "load_mesh_file", "save_mesh", "MESH_FORMATS", "read_ply", "cloud_ply_bytes", "mesh_ply_bytes",
           "IMAGE_SUFFIXES", "Capture", "list_images", "load_capture", "pattern_spec_for", "read_stack",
           "save_decoded", "POSES_SCHEMA", "load_poses", "save_poses", "ToFFolder", "load_ground_truth",
           "load_tof_folder", "SESSION_SCHEMA", "CaptureSettings", "ProcessResult",
           "ScanPlan", "Session", "SessionView", "SimulatorSettings", "load_session", "view_folder", "verify_views",
           "SessionLocked", "session_lock", "SUMMARY_SCHEMA"]
