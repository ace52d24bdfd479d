#!/usr/bin/env bash
# Side by side with OpenCV on random PnP families (issue 34): roitrack's static pose solver against solvePnP (SQPNP,
# IPPE, EPNP + solvePnPRefineLM, AP3P) on seeded random problems of eight families, with --check. See bench/README.md.
#
#   bash bench/pnp_families.sh [options of bench/pnp_families.py, e.g. --seed 2 --per-family 100 --json OUT]
#
# Makes the virtual environment target/opencv-venv (the same as bench/opencv_compare.sh, same pinned packages; needs
# network access to PyPI the first time), builds roitrack with the lab (feature `lab`) in release mode and runs bench/pnp_families.py with --check:
# exit status 0 when roitrack does as well as the best OpenCV method on every family.
set -euo pipefail
cd "$(dirname "$0")/.."

venv=target/opencv-venv
# Pinned for reproducible figures (as in bench/opencv_compare.sh and scripts/setup-test-deps); override with
# OPENCV_COMPARE_PACKAGES="opencv-python-headless numpy".
packages=${OPENCV_COMPARE_PACKAGES:-"opencv-python-headless==5.0.0.93 numpy==2.4.6"}
python=${PYTHON:-python3}

if ! "$venv/bin/python" -c "import cv2, numpy" 2>/dev/null; then
    echo "pnp_families: making $venv with $packages" >&2
    mkdir -p target
    "$python" -m venv "$venv"
    # shellcheck disable=SC2086 # the package list is meant to split into words
    "$venv/bin/pip" install --quiet --disable-pip-version-check $packages
fi

echo "pnp_families: cargo build --release -p roitrack-cli --features lab" >&2
cargo build --release --quiet -p roitrack-cli --features lab
bin="${CARGO_TARGET_DIR:-target}/release/roitrack"

exec "$venv/bin/python" bench/pnp_families.py --roitrack "$bin" --check "$@"
