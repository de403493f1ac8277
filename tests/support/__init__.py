"""What several test files share and no test file is: the fake depthai (fake_depthai), the small reference session
(sessions), the small rigs (small_rigs), the command line as a child process (cli_runs), files read counted from the
kernel (file_reads), headless Chromium (chromium), the web app on a free port (ui_server) and a cross-origin page
(attacker_server), the shared data folder (shared_data), and the fixtures of single rooms (bearing_networks,
bundle_problems, calib_tolerances, depthai_names, fits, laser_lines). Imported as ``support.NAME``: tests/ is on
sys.path, put there by pytest for tests/conftest.py (rootdir conftest, "prepend" import mode), in every xdist worker
too; a script outside pytest (benchmarks/) puts tests/ there itself."""
