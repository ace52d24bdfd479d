#!/usr/bin/env python3
"""The Python package against the Rust library on the same job: the orthoglide scenario's simulated measurements
(seed 1, 0.1 px, 4 kHz, 19,655 measurements) tracked by the default Kalman filter with an estimate every 10.

- track(): `roitrack.track(camera, target, measurements)` from Python, every estimate returned as arrays, against the
  same call from Rust in the same process (`roitrack lab bench --json`'s `track_library_meas_per_s`: the library's
  `track` over the measurements in memory, every estimate collected). Each round runs Rust, track() and push()
  back to back; the ratio is Python's time over Rust's, the median over the rounds (the machine's load changes
  between rounds more than within one).
- push(): `Tracker.push(t, id, u, v)` called once per measurement from a Python loop, against the Rust figure per
  measurement: what a push costs on top of the Rust call (the Python call, the loop, building an Estimate when one
  is due), the median over the rounds.

Targets (the Python package's): track() at least 300,000 measurements/s and within 1.2x of Rust; push() at most 1 us on top of
the Rust call. The Rust side is in a wheel built with the lab (the feature `lab`); run with it installed:

    target/py-venv/bin/maturin build --release -m crates/roitrack-python/Cargo.toml --features lab --out target/lab-wheels
    target/py-venv/bin/pip install --force-reinstall --no-deps target/lab-wheels/roitrack-*.whl
    target/py-venv/bin/python bench/python_bench.py [--rounds N] [--json] [--check]

--check exits with status 1 naming the targets that do not hold.
"""

import argparse
import json
import statistics
import sys
import time

import roitrack
from roitrack import _roitrack

TARGET_MEAS_PER_S = 300_000.0
TARGET_RATIO = 1.2
TARGET_PUSH_OVERHEAD_US = 1.0


def best_track_seconds(camera: roitrack.Camera, target: roitrack.Target, measurements, runs: int) -> float:
    best = float("inf")
    for _ in range(runs):
        start = time.perf_counter()
        roitrack.track(camera, target, measurements, estimator="kalman", every=10)
        best = min(best, time.perf_counter() - start)
    return best


def best_push_seconds(camera: roitrack.Camera, target: roitrack.Target, rows: list, runs: int) -> float:
    best = float("inf")
    for _ in range(runs):
        tracker = roitrack.Tracker(camera, target, estimator="kalman", every=10)
        push = tracker.push
        start = time.perf_counter()
        for t, i, u, v in rows:
            push(t, i, u, v)
        best = min(best, time.perf_counter() - start)
    return best


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rounds", type=int, default=21, help="rounds of back-to-back runs (default 21)")
    parser.add_argument("--json", action="store_true", help="print one JSON object instead of a table")
    parser.add_argument("--check", action="store_true", help="exit with status 1 if a target does not hold")
    args = parser.parse_args()
    if not hasattr(_roitrack, "_bench_track_library"):
        print("python_bench: this roitrack wheel has no lab: build it with --features lab (see the docstring)", file=sys.stderr)
        return 2

    sim = roitrack.simulate("orthoglide", seed=1)
    camera, target, measurements = sim["camera"], sim["target"], sim["measurements"]
    n = len(measurements)
    rows = [(t, int(i), u, v) for t, i, u, v in measurements.tolist()]
    # Rounds of three back-to-back runs (Rust, Python track(), Python push()), so that each round's ratios compare runs
    # made under the same load; the ratios reported are the medians over the rounds, the rates the best runs.
    rust_s, track_s, push_s = [], [], []
    for _ in range(max(1, args.rounds)):
        rust_s.append(n / _roitrack._bench_track_library(1))
        track_s.append(best_track_seconds(camera, target, measurements, 1))
        push_s.append(best_push_seconds(camera, target, rows, 1))
    ratio = statistics.median(p / r for p, r in zip(track_s, rust_s))
    push_overhead_us = statistics.median(1e6 * (p - r) / n for p, r in zip(push_s, rust_s))
    rust_rate, python_rate, push_rate = n / min(rust_s), n / min(track_s), n / min(push_s)
    rust_us = 1e6 / rust_rate
    push_us = 1e6 / push_rate
    figures = {
        "measurements": n,
        "track_library_meas_per_s": round(rust_rate),
        "python_track_meas_per_s": round(python_rate),
        "python_track_ratio": round(ratio, 4),
        "rust_us_per_measurement": round(rust_us, 4),
        "python_push_us_per_measurement": round(push_us, 4),
        "python_push_overhead_us": round(push_overhead_us, 4),
        "rounds": args.rounds,
    }
    failures = []
    if python_rate < TARGET_MEAS_PER_S:
        failures.append(f"track() {python_rate:.0f} measurements/s < {TARGET_MEAS_PER_S:.0f}")
    if ratio > TARGET_RATIO:
        failures.append(f"track() takes {ratio:.3f}x Rust's time > {TARGET_RATIO}x")
    if push_overhead_us > TARGET_PUSH_OVERHEAD_US:
        failures.append(f"push() adds {push_overhead_us:.3f} us > {TARGET_PUSH_OVERHEAD_US} us")
    if args.json:
        print(json.dumps(figures))
    else:
        print(f"orthoglide, seed 1: {n} measurements, Kalman filter, an estimate every 10; {args.rounds} rounds (rates: "
              "the best run; ratio and overhead: the median of each round's)")
        print(f"{'':<44} {'meas/s':>12} {'us/meas':>9}")
        print(f"{'Rust: library track() in memory':<44} {rust_rate:>12.0f} {rust_us:>9.3f}")
        print(f"{'Python: roitrack.track()':<44} {python_rate:>12.0f} {1e6 / python_rate:>9.3f}"
              f"   {ratio:.3f}x Rust's time (target <= {TARGET_RATIO}x, >= 300,000/s)")
        print(f"{'Python: Tracker.push() in a for loop':<44} {push_rate:>12.0f} {push_us:>9.3f}"
              f"   +{push_overhead_us:.3f} us a measurement (target <= {TARGET_PUSH_OVERHEAD_US} us)")
        print("targets met" if not failures else "NOT met: " + "; ".join(failures))
    return 1 if args.check and failures else 0


if __name__ == "__main__":
    sys.exit(main())
