"""Shared fixtures: the command-line tool built from the same sources, and a simulated recording written by it."""

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[3]


def roitrack_binary() -> Path:
    """The `roitrack` binary of this checkout (ROITRACK_BIN overrides; scripts/test builds target/release/roitrack)."""
    path = Path(os.environ.get("ROITRACK_BIN", REPO / "target" / "release" / "roitrack"))
    if not path.exists():
        pytest.fail(f"{path} is missing: build it with `cargo build --release -p roitrack-cli` (scripts/test does)")
    return path


def run_cli(*args: object, check: bool = True) -> subprocess.CompletedProcess:
    """Runs the command-line tool; with `check`, fails the test on a non-zero exit, showing its stderr."""
    result = subprocess.run(
        [str(roitrack_binary()), *map(str, args)], capture_output=True, text=True, timeout=600
    )
    if check and result.returncode != 0:
        pytest.fail(f"roitrack {' '.join(map(str, args))} failed:\n{result.stderr}")
    return result


def cli_error(*args: object) -> str:
    """The message of a failing command (its `roitrack: error: ...` line, without the prefix)."""
    result = run_cli(*args, check=False)
    assert result.returncode != 0, f"roitrack {args} succeeded"
    line = [l for l in result.stderr.splitlines() if l.startswith("roitrack: error: ")][-1]
    return line[len("roitrack: error: ") :]


def read_measurements(path: Path) -> np.ndarray:
    return np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)


def read_tum(path: Path) -> np.ndarray:
    return np.loadtxt(path, ndmin=2)


def read_csv(path: Path) -> np.ndarray:
    return np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)


def cli_json(*args: object) -> dict:
    return json.loads(run_cli(*args).stdout)


@pytest.fixture(scope="session")
def orthoglide(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """`roitrack simulate --scenario orthoglide --seed 1` written to a folder."""
    out = tmp_path_factory.mktemp("orthoglide")
    run_cli("simulate", "--scenario", "orthoglide", "--seed", 1, "--out", out)
    return out
