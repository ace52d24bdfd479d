#!/usr/bin/env bash
# Peer comparison, one command: OpenCV's solvePnP (ITERATIVE, SQPNP, EPNP, IPPE, through opencv-python-headless) and
# roitrack's static pose solver on the identical stored problem, timed in the same run. See bench/README.md.
#
#   bash bench/opencv_compare.sh [options of bench/opencv_compare.py, e.g. --repeats 50 --instances 200]
#
# Makes a virtual environment under target/ (opencv-python-headless and numpy from PyPI; needs network access to PyPI
# the first time), builds roitrack with the lab (feature `lab`) in release mode, writes the problem to target/opencv-compare/problem.json, prints
# the table and writes target/opencv-compare/summary.json. Exit status 0 when the accuracy checks pass.
set -euo pipefail
cd "$(dirname "$0")/.."

venv=target/opencv-venv
# Pinned for reproducible figures; override with OPENCV_COMPARE_PACKAGES="opencv-python-headless numpy".
packages=${OPENCV_COMPARE_PACKAGES:-"opencv-python-headless==5.0.0.93 numpy==2.4.6"}
python=${PYTHON:-python3}

if ! "$venv/bin/python" -c "import cv2, numpy" 2>/dev/null; then
    echo "opencv_compare: making $venv with $packages" >&2
    mkdir -p target
    "$python" -m venv "$venv"
    # shellcheck disable=SC2086 # the package list is meant to split into words
    "$venv/bin/pip" install --quiet --disable-pip-version-check $packages
fi

echo "opencv_compare: cargo build --release -p roitrack-cli --features lab" >&2
cargo build --release --quiet -p roitrack-cli --features lab
bin="${CARGO_TARGET_DIR:-target}/release/roitrack"

out=target/opencv-compare
mkdir -p "$out"
exec "$venv/bin/python" bench/opencv_compare.py \
    --roitrack "$bin" \
    --problem "$out/problem.json" \
    --json-out "$out/summary.json" \
    "$@"
