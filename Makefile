# rangekit: two commands on a fresh machine.
#   make scan   run the main job (simulated rig, no hardware, no arguments)
#   make test   run the test suite
#   make ui     then: the rig in a browser (rangekit ui; prints the URL to open)
# Each creates .venv and installs what is missing on first use.

PYTHON ?= python3
VENV   ?= .venv
BIN    := $(VENV)/bin
STAMP  := $(VENV)/.rangekit-installed

.PHONY: setup test test-bare test-slow scan ui bench clean browser docs-figures bytecode peers

setup: $(STAMP)

$(STAMP): pyproject.toml
	@# open3d needs the system library libusb-1.0 (Debian: libusb-1.0-0).
	@if ! ldconfig -p 2>/dev/null | grep -q 'libusb-1\.0\.so'; then \
	  echo "installing libusb-1.0-0 (needed by open3d)"; \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libusb-1.0-0) >/dev/null; \
	  else echo "please install libusb-1.0-0 (e.g. sudo apt-get install libusb-1.0-0)"; exit 1; fi; \
	fi
	@[ -x $(BIN)/python ] || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install -q --upgrade pip
	$(BIN)/python -m pip install -q -e ".[test]"
	@touch $(STAMP)

bytecode: $(STAMP)
	@# The package's compiled modules, as a pip install writes them: where PYTHONDONTWRITEBYTECODE is set (as in
	@# some containers) every start of rangekit otherwise compiles its 170 modules again (about 0.15 CPU-s).
	@$(BIN)/python -m compileall -q -j 0 rangekit sim drivers calib >/dev/null

test: $(STAMP) browser bytecode
	@# Two pytest-xdist workers, one a core: 6 minutes instead of 8.5 here. --dist loadgroup: the memory-heavy modules
	@# (tests/conftest.py's MEMORY_HEAVY) run on one worker, one after another; the machine's used memory rose 3.6 GB
	@# at its peak (4.8 GB before; docs/benchmarks.md, "Issue 51, eighth stop: make test's memory").
	$(BIN)/python -m pytest -q -m "not slow" -n 2 --dist loadgroup

test-bare: $(STAMP) browser bytecode
	@# The suite as a bare clone sees it: the shared real data hidden (an empty RANGEKIT_DATA), every test that
	@# needs it skipped with a reason naming the folder. CI runs it.
	mkdir -p build/no-shared-data
	RANGEKIT_DATA=$(CURDIR)/build/no-shared-data $(BIN)/python -m pytest -q -m "not slow" -n 2 --dist loadgroup -rs

test-slow: $(STAMP) browser bytecode peers
	@# The full-size cases (whole calibration, 6-view scans to a mesh, 12-view registration, ...): CI runs them.
	$(BIN)/python -m pytest -q -m slow

peers:
	@# OpenCV contrib's structured-light module in .venv-bench (it cannot share .venv: both provide cv2), for the
	@# tests and benchmarks that run OpenCV's own pipeline beside rangekit's; they skip, saying so, without it.
	-bash benchmarks/coded/setup_opencv_contrib.sh

browser:
	@# Headless Chromium + chromedriver (Debian packages) for the report test in tests/app/scan/test_scan.py and
	@# tests/test_chromium_harness.py; without them (not root, no apt) those tests skip.
	@if [ ! -x /usr/bin/chromium ] || [ ! -x /usr/bin/chromedriver ]; then \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null; then \
	    echo "installing chromium and chromium-driver (for the browser test)"; \
	    (apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver) >/dev/null \
	      || echo "note: could not install chromium; the browser test will skip"; \
	  else echo "note: chromium/chromedriver missing (sudo apt-get install chromium chromium-driver); the browser test will skip"; fi; \
	fi

scan: $(STAMP) bytecode
	@# A full simulated scan to a mesh; a second run resumes (and reprocesses) scan1/.
	@if [ -f scan1/session.json ]; then $(BIN)/rangekit scan --resume scan1; else $(BIN)/rangekit scan --out scan1; fi

ui: $(STAMP) bytecode
	@# The web app on the simulated rig (Live, Check, Calibrate, Scan, Sessions, Registration), sessions in ./sessions.
	@mkdir -p sessions
	$(BIN)/rangekit ui --sessions sessions

bench: $(STAMP)
	$(BIN)/python benchmarks/sim/bench_render.py

clean:
	rm -rf $(VENV) .venv-bench *.egg-info .pytest_cache

docs-figures: $(STAMP) browser bytecode
	@# Reruns every figure quoted in README.md and docs/ (the blocks between <!-- figure: COMMAND --> and
	@# <!-- /figure -->) and writes the fresh output in place: about 19 minutes on an idle 2-core machine (the first run
	@# also installs OpenCV-contrib into .venv-bench for the decoding benchmark's peer: it needs the package index).
	$(BIN)/python tools/docs_figures.py
