"""The work behind each command: acquisition sessions, processing a session into a mesh and its report,
one view's reconstruction, registering scan files, simulated captures, calibration, depth outputs.

(:mod:`rangekit.app.snapshot`, the headless renderer, is imported by its own path.)
"""

from rangekit.app.acquire import acquire
from rangekit.app.calibration import Calibration, calibrate
from rangekit.app.photometric_run import photometric_files
from rangekit.app.picture import Picture, render_file
from rangekit.app.process import FUSION_METHODS, Evaluation, Evaluator, process_session
from rangekit.app.range_runs import DepthRun, stereo_depth_files, tof_depth_files, write_depth_outputs
from rangekit.app.reconstruct import Reconstruction, reconstruct_view
from rangekit.app.register_files import RegisterReport, parse_init, register_files
from rangekit.app.report import view_graph_svg, write_report
from rangekit.app.scan import ScanSetup, prepare_scan, process_scan, session_evaluator
from rangekit.app.simulate import render_projector_capture, render_stereo_capture, render_tof_capture
from rangekit.app.view_cache import ViewMaps, view_cloud, white_frame_index

__all__ = ["acquire", "Calibration", "calibrate", "photometric_files", "Picture", "render_file", "FUSION_METHODS",
           "Evaluation", "Evaluator", "process_session", "DepthRun", "stereo_depth_files", "tof_depth_files", "write_depth_outputs",
           "Reconstruction", "reconstruct_view", "RegisterReport", "parse_init", "register_files", "view_graph_svg",
           "write_report", "ScanSetup", "prepare_scan", "process_scan", "session_evaluator",
           "render_projector_capture", "render_stereo_capture", "render_tof_capture", "ViewMaps", "view_cloud",
           "white_frame_index"]
