#!/usr/bin/env bash
# Peer comparison, one command: OpenCV's solvePnP (ITERATIVE, SQPNP, EPNP, IPPE, through opencv-python-headless) and
# roitrack's static pose solver on the identical stored problem, timed in the same run. See bench/README.md.
#
#   bash bench/opencv_compare.sh [options of bench/opencv_compare.py, e.g. --repeats 50 --instances 200]
#
# Makes the virtual environment target/opencv-venv and builds roitrack with the lab (bench/opencv_env.sh), writes the
# problem to target/opencv-compare/problem.json, prints the table and writes target/opencv-compare/summary.json. Exit status 0 when the accuracy checks pass.
set -euo pipefail
cd "$(dirname "$0")/.."

name=opencv_compare
# shellcheck source=bench/opencv_env.sh
source bench/opencv_env.sh

out=target/opencv-compare
mkdir -p "$out"
exec "$venv/bin/python" bench/opencv_compare.py \
    --roitrack "$bin" \
    --problem "$out/problem.json" \
    --json-out "$out/summary.json" \
    "$@"
