#!/usr/bin/env bash
# Rolling shutter against global shutter on frames from a renderer written apart from roitrack's
# (bench/rs_outside_render.py, numpy only). See bench/README.md.
#
#   bash bench/rs_outside_render.sh [--seeds "1 2 3"] [--frames 120] [--line-delay-s 30e-6] [--out target/rs-outside]
#       [--peak-speed-mps 0.8] [--peak-rate-rps 3] [--exposure-s 1e-3]
#
# For each seed: renders one motion as rolling-shutter and global-shutter PGM frames (same noise), tracks them with
# the release `roitrack track --images` (global; rolling with the default offline smoothing; rolling with
# --no-rs-smoothing), scores each with `roitrack eval` over every estimate and after the first 5, and prints the
# table. Exit status 0 when the rolling-shutter position RMSE is at most max(1.5 x global shutter, 0.2 mm) on every
# seed and both scorings.
set -euo pipefail
cd "$(dirname "$0")/.."

seeds="1 2 3"
frames=120
delay=30e-6
out=target/rs-outside
speed=0.8
rate=3
exposure=1e-3
while [ $# -gt 0 ]; do
    case "$1" in
        --seeds) seeds="$2"; shift 2 ;;
        --frames) frames="$2"; shift 2 ;;
        --line-delay-s) delay="$2"; shift 2 ;;
        --out) out="$2"; shift 2 ;;
        --peak-speed-mps) speed="$2"; shift 2 ;;
        --peak-rate-rps) rate="$2"; shift 2 ;;
        --exposure-s) exposure="$2"; shift 2 ;;
        *) echo "rs_outside_render.sh: unknown option $1" >&2; exit 2 ;;
    esac
done

# numpy: the OpenCV comparison's environment when it is there, else one of our own
venv=target/opencv-venv
if ! "$venv/bin/python" -c "import numpy" 2>/dev/null; then
    venv=target/rs-venv
    if ! "$venv/bin/python" -c "import numpy" 2>/dev/null; then
        python3 -m venv "$venv"
        "$venv/bin/pip" install --quiet numpy
    fi
fi
py="$venv/bin/python"

cargo build --release -p roitrack-cli
bin="${CARGO_TARGET_DIR:-target}/release/roitrack"

mkdir -p "$out"
dirs=()
for seed in $seeds; do
    d="$out/seed$seed"
    dirs+=("$d")
    rm -rf "$d"
    "$py" bench/rs_outside_render.py render --seed "$seed" --out "$d" --frames "$frames" --line-delay-s "$delay" \
        --peak-speed-mps "$speed" --peak-rate-rps "$rate" --exposure-s "$exposure"
    common=(--camera "$d/camera.yaml" --target "$d/target.csv" --timestamps "$d/timestamps.csv" --exposure-s "$exposure")
    "$bin" track "${common[@]}" --images "$d/frames_gs" --shutter global \
        --poses "$d/gs.tum" --twists "$d/gs.csv" --diagnostics "$d/gs_diag.csv" 2>"$d/gs.log"
    "$bin" track "${common[@]}" --images "$d/frames_rs" --shutter rolling --line-delay-s "$delay" \
        --poses "$d/rs.tum" --twists "$d/rs.csv" --diagnostics "$d/rs_diag.csv" 2>"$d/rs.log"
    "$bin" track "${common[@]}" --images "$d/frames_rs" --shutter rolling --line-delay-s "$delay" --no-rs-smoothing \
        --poses "$d/rs_causal.tum" --twists "$d/rs_causal.csv" --diagnostics "$d/rs_causal_diag.csv" 2>"$d/rs_causal.log"
    for run in gs rs rs_causal; do
        "$bin" eval --truth "$d" --poses "$d/$run.tum" --twists "$d/$run.csv" --json >"$d/eval_${run}_all.json"
        tail -n +6 "$d/$run.tum" >"$d/${run}_after5.tum"
        { head -n 1 "$d/$run.csv"; tail -n +7 "$d/$run.csv"; } >"$d/${run}_after5.csv"
        "$bin" eval --truth "$d" --poses "$d/${run}_after5.tum" --twists "$d/${run}_after5.csv" --json \
            >"$d/eval_${run}_after5.json"
    done
done
"$py" bench/rs_outside_render.py table --runs "${dirs[@]}" --json-out "$out/summary.json"
