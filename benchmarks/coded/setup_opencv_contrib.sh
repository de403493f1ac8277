#!/usr/bin/env bash
# Create the peer venv for bench_decode.py: OpenCV contrib (structured_light) next to, not inside, .venv.
#
#     bash benchmarks/coded/setup_opencv_contrib.sh
#
# opencv-contrib-python-headless and opencv-python-headless both install the `cv2` module, so they cannot
# share one environment. This script is idempotent: it creates /work/main/.venv-bench only if missing and
# installs numpy + opencv-contrib-python-headless only if `cv2.structured_light` is not importable yet.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
VENV="${RANGEKIT_BENCH_VENV:-$ROOT/.venv-bench}"
PY="$VENV/bin/python"

if [ ! -x "$PY" ]; then
    echo "creating $VENV"
    python3 -m venv "$VENV"
fi

if ! "$PY" -c "import numpy, cv2; cv2.structured_light.GrayCodePattern.create" >/dev/null 2>&1; then
    echo "installing numpy and opencv-contrib-python-headless into $VENV"
    "$PY" -m pip install --quiet --upgrade pip
    "$PY" -m pip install --quiet numpy opencv-contrib-python-headless
fi

"$PY" -c "import cv2, numpy; print(f'OpenCV {cv2.__version__} (contrib, structured_light), numpy {numpy.__version__}, in $VENV')"
