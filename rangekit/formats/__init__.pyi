"""The names of ``rangekit.formats``, each loaded from its module on first use (rangekit._runtime.lazy.attach_stub)."""

from .clouds import (load_cloud as load_cloud, save_cloud as save_cloud, CLOUD_READERS as CLOUD_READERS,
    CLOUD_WRITERS as CLOUD_WRITERS, RangeGrid as RangeGrid, load_range_grid as load_range_grid)
from .meshes import load_mesh as load_mesh, save_mesh as save_mesh, MESH_FORMATS as MESH_FORMATS
from .ply import read_ply as read_ply
from .ply_write import (cloud_ply_bytes as cloud_ply_bytes, mesh_ply_bytes as mesh_ply_bytes,
    write_cloud_ply as write_cloud_ply)
from .capture import (IMAGE_SUFFIXES as IMAGE_SUFFIXES, Capture as Capture, list_images as list_images,
    load_capture as load_capture, pattern_spec_for as pattern_spec_for, read_stack as read_stack,
    save_decoded as save_decoded)
from .poses import POSES_SCHEMA as POSES_SCHEMA, load_poses as load_poses, save_poses as save_poses
from .range_files import (ToFFolder as ToFFolder, load_ground_truth as load_ground_truth,
    load_tof_folder as load_tof_folder)
from .sessions.session import (SESSION_SCHEMA as SESSION_SCHEMA, CaptureSettings as CaptureSettings,
    ScanPlan as ScanPlan, Session as Session, SessionView as SessionView, SimulatorSettings as SimulatorSettings,
    load_session as load_session, view_folder as view_folder)
from .sessions.summary import ProcessResult as ProcessResult, SUMMARY_SCHEMA as SUMMARY_SCHEMA
from .sessions.check import verify_views as verify_views
from .sessions.lock import SessionLocked as SessionLocked, session_lock as session_lock
