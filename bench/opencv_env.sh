# Sourced by the OpenCV comparisons (bench/opencv_compare.sh, bench/pnp_families.sh): makes the virtual environment
# target/opencv-venv with OpenCV and numpy if it is not there (needs network access to PyPI the first time), builds
# roitrack with the lab (feature `lab`) in release mode, and sets `venv` and `bin` (the roitrack binary).
# `name` (the calling script's) prefixes the messages.

venv=target/opencv-venv
# Pinned for reproducible figures (as in scripts/setup-test-deps); override with
# OPENCV_COMPARE_PACKAGES="opencv-python-headless numpy".
packages=${OPENCV_COMPARE_PACKAGES:-"opencv-python-headless==5.0.0.93 numpy==2.4.6"}
python=${PYTHON:-python3}

if ! "$venv/bin/python" -c "import cv2, numpy" 2>/dev/null; then
    echo "$name: making $venv with $packages" >&2
    mkdir -p target
    "$python" -m venv "$venv"
    # shellcheck disable=SC2086 # the package list is meant to split into words
    "$venv/bin/pip" install --quiet --disable-pip-version-check $packages
fi

echo "$name: cargo build --release -p roitrack-cli --features lab" >&2
cargo build --release --quiet -p roitrack-cli --features lab
bin="${CARGO_TARGET_DIR:-target}/release/roitrack"
