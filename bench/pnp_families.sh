#!/usr/bin/env bash
# Side by side with OpenCV on random PnP families: roitrack's static pose solver against solvePnP (SQPNP,
# IPPE, EPNP + solvePnPRefineLM, AP3P) on seeded random problems of eight families, with --check. See bench/README.md.
#
#   bash bench/pnp_families.sh [options of bench/pnp_families.py, e.g. --seed 2 --per-family 100 --json OUT]
#
# Makes the virtual environment target/opencv-venv and builds roitrack with the lab (bench/opencv_env.sh), then runs
# bench/pnp_families.py with --check: exit status 0 when roitrack does as well as the best OpenCV method on every family.
set -euo pipefail
cd "$(dirname "$0")/.."

name=pnp_families
# shellcheck source=bench/opencv_env.sh
source bench/opencv_env.sh

exec "$venv/bin/python" bench/pnp_families.py --roitrack "$bin" --check "$@"
