"""Files a user keeps: point clouds (PLY, PCD, XYZ, NPY) and meshes (PLY, OBJ, STL) with one PLY reader and
writer, capture folders, poses.json, ToF capture folders, scan sessions (session.json, summary.json).

The names below are loaded on first use (PEP 562): importing one module of this package, e.g.
``rangekit.formats.capture`` for ``rangekit decode``, does not import the others (clouds and meshes pull in
``rangekit.surface`` and scipy.spatial, about 0.6 s)."""

from rangekit._runtime.lazy import lazy_exports

_EXPORTS = {
    "capture": ("IMAGE_SUFFIXES", "Capture", "list_images", "load_capture", "pattern_spec_for", "read_stack",
                "save_decoded"),
    "clouds": ("CLOUD_READERS", "CLOUD_WRITERS", "RangeGrid", "load_cloud", "load_range_grid", "save_cloud"),
    "meshes": ("MESH_FORMATS", "load_mesh", "save_mesh"),
    "ply": ("read_ply",),
    "ply_write": ("cloud_ply_bytes", "mesh_ply_bytes", "write_cloud_ply"),
    "poses": ("POSES_SCHEMA", "load_poses", "save_poses"),
    "range_files": ("ToFFolder", "load_ground_truth", "load_tof_folder"),
    "sessions.session": ("SESSION_SCHEMA", "CaptureSettings", "ScanPlan", "Session", "SessionView", "SimulatorSettings",
                "load_session", "view_folder"),
    "sessions.check": ("verify_views",),
    "sessions.lock": ("SessionLocked", "session_lock"),
    "sessions.summary": ("SUMMARY_SCHEMA", "ProcessResult"),
}
_MODULE_OF = {name: module for module, names in _EXPORTS.items() for name in names}

__all__ = ["load_cloud", "save_cloud", "CLOUD_READERS", "CLOUD_WRITERS", "RangeGrid", "load_range_grid",
           "load_mesh", "save_mesh", "MESH_FORMATS", "read_ply", "cloud_ply_bytes", "mesh_ply_bytes",
           "write_cloud_ply",
           "IMAGE_SUFFIXES", "Capture", "list_images", "load_capture", "pattern_spec_for", "read_stack",
           "save_decoded", "POSES_SCHEMA", "load_poses", "save_poses", "ToFFolder", "load_ground_truth",
           "load_tof_folder", "SESSION_SCHEMA", "CaptureSettings", "ProcessResult",
           "ScanPlan", "Session", "SessionView", "SimulatorSettings", "load_session", "view_folder", "verify_views",
           "SessionLocked", "session_lock", "SUMMARY_SCHEMA"]

__getattr__, __dir__ = lazy_exports(__name__, _MODULE_OF, __all__)
