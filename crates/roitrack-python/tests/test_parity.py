"""The Python package gives the command line's results on the same files: poses, twists and covariances of every
estimator (to 1e-12), the simulator's measurements and truth, and `roitrack eval`'s metrics."""

from pathlib import Path

import numpy as np
import pytest

import roitrack
from conftest import cli_json, read_csv, read_measurements, read_tum, run_cli

# Each case: keywords of roitrack.track and the same options of `roitrack track`.
CASES = [
    ({}, []),
    ({"adapt": "none", "accel_psd": 5.0, "noise_px": 0.2}, ["--adapt", "none", "--accel-psd", "5", "--noise-px", "0.2"]),
    ({"estimator": "paper", "gain": 0.5}, ["--estimator", "paper", "--gain", "0.5"]),
    ({"motion_model": "constant-acceleration", "angular_jerk_psd": 500.0},
     ["--motion-model", "constant-acceleration", "--angular-jerk-psd", "500"]),
    ({"estimator": "exact", "iterations": 2, "window": 32}, ["--estimator", "exact", "--iterations", "2", "--window", "32"]),
    ({"estimator": "batch", "every": 20, "robust": "huber"}, ["--estimator", "batch", "--every", "20", "--robust", "huber"]),
    ({"estimator": "static", "min_conditioning": 1e-3}, ["--estimator", "static", "--min-conditioning", "0.001"]),
]


def covariance_from_csv(rows: np.ndarray) -> np.ndarray:
    i, j = np.triu_indices(12)
    cov = np.empty((len(rows), 12, 12))
    cov[:, i, j] = rows[:, 1:]
    cov[:, j, i] = rows[:, 1:]
    return cov


@pytest.mark.parametrize("keywords,options", CASES, ids=[str(k) for k, _ in CASES])
def test_track_equals_the_command_line(orthoglide: Path, tmp_path: Path, keywords: dict, options: list) -> None:
    poses, twists, cov = tmp_path / "poses.tum", tmp_path / "twists.csv", tmp_path / "cov.csv"
    run_cli(
        "track", "--camera", orthoglide / "camera.yaml", "--target", orthoglide / "target.csv",
        "--measurements", orthoglide / "measurements.csv", "--poses", poses, "--twists", twists,
        "--covariance", cov, *options,
    )
    camera = roitrack.Camera.from_yaml(orthoglide / "camera.yaml")
    target = roitrack.Target.from_csv(str(orthoglide / "target.csv"))
    res = roitrack.track(camera, target, read_measurements(orthoglide / "measurements.csv"), **keywords)
    tum, tw, cv = read_tum(poses), read_csv(twists), read_csv(cov)
    assert len(res["t_s"]) == len(tum) > 100
    np.testing.assert_allclose(res["t_s"], tum[:, 0], rtol=0, atol=1e-12)
    np.testing.assert_allclose(res["position_m"], tum[:, 1:4], rtol=0, atol=1e-12)
    np.testing.assert_allclose(res["quaternion_xyzw"], tum[:, 4:8], rtol=0, atol=1e-12)
    np.testing.assert_allclose(res["velocity_mps"], tw[:, 1:4], rtol=0, atol=1e-12)
    np.testing.assert_allclose(res["angular_velocity_radps"], tw[:, 4:7], rtol=0, atol=1e-12)
    np.testing.assert_allclose(res["covariance"], covariance_from_csv(cv), rtol=1e-12, atol=0, equal_nan=True)
    assert res["status"].shape == res["t_s"].shape
    assert set(res["status"]) <= {"converging", "tracking", "degenerate", "disputed", "lost"}


def test_push_equals_track(orthoglide: Path) -> None:
    """One measurement at a time gives what track() gives (the simulated ROIs all have their own times)."""
    camera = roitrack.Camera.from_yaml(orthoglide / "camera.yaml")
    target = roitrack.Target.from_csv(orthoglide / "target.csv")
    measurements = read_measurements(orthoglide / "measurements.csv")
    res = roitrack.track(camera, target, measurements)
    tracker = roitrack.Tracker(camera, target, estimator="kalman", every=10)
    estimates = [e for row in measurements if (e := tracker.push(row[0], int(row[1]), row[2], row[3])) is not None]
    assert tracker.measurements == len(measurements)
    assert len(estimates) == len(res["t_s"])
    for k in (0, 1, len(estimates) // 2, len(estimates) - 1):
        e = estimates[k]
        assert e.t_s == res["t_s"][k]
        assert np.array_equal(e.position_m, res["position_m"][k])
        assert np.array_equal(e.quaternion_xyzw, res["quaternion_xyzw"][k])
        assert np.array_equal(e.velocity_mps, res["velocity_mps"][k])
        assert np.array_equal(e.angular_velocity_radps, res["angular_velocity_radps"][k])
        assert np.array_equal(e.covariance, res["covariance"][k])
        assert e.status == res["status"][k]
        assert e.residual_px == res["residual_px"][k] and e.conditioning == res["conditioning"][k]
        assert e.covariance.shape == (12, 12) and e.position_m.shape == (3,) and e.quaternion_xyzw.shape == (4,)


def test_simulate_equals_the_command_line(orthoglide: Path) -> None:
    sim = roitrack.simulate("orthoglide", seed=1)
    np.testing.assert_array_equal(sim["measurements"], read_measurements(orthoglide / "measurements.csv"))
    tum, tw = read_tum(orthoglide / "gt_poses.tum"), read_csv(orthoglide / "gt_twists.csv")
    np.testing.assert_array_equal(sim["gt_t_s"], tum[:, 0])
    np.testing.assert_array_equal(sim["gt_position_m"], tum[:, 1:4])
    np.testing.assert_array_equal(sim["gt_quaternion_xyzw"], tum[:, 4:8])
    np.testing.assert_array_equal(sim["gt_velocity_mps"], tw[:, 1:4])
    np.testing.assert_array_equal(sim["gt_angular_velocity_radps"], tw[:, 4:7])
    camera = roitrack.Camera.from_yaml(orthoglide / "camera.yaml")
    assert (sim["camera"].width, sim["camera"].fx, sim["camera"].distortion) == (camera.width, camera.fx, camera.distortion)
    np.testing.assert_array_equal(sim["target"].points_m, roitrack.Target.from_csv(orthoglide / "target.csv").points_m)


def test_simulate_options_equal_the_command_line(tmp_path: Path) -> None:
    run_cli("simulate", "--scenario", "spin", "--seed", 3, "--noise-px", 0.3, "--rate-hz", 2000, "--order", "random",
            "--drop", 0.1, "--outliers", 0.05, "--out", tmp_path)
    sim = roitrack.simulate("spin", seed=3, noise_px=0.3, rate_hz=2000.0, order="random", drop=0.1, outliers=0.05)
    np.testing.assert_array_equal(sim["measurements"], read_measurements(tmp_path / "measurements.csv"))


def test_simulate_with_own_camera_and_target() -> None:
    camera = roitrack.Camera(1280, 1024, 1800.0, 1800.0, 640.0, 512.0, distortion=[-0.1, 0.01, 0.0, 0.0, 0.0])
    grid = np.array([[x, y, 0.0] for y in (-0.04, 0.0, 0.04) for x in (-0.04, 0.0, 0.04)])
    target = roitrack.Target(grid, ids=list(range(10, 19)), diameters_m=[0.006] * 9)
    sim = roitrack.simulate("orthoglide", camera=camera, target=target)
    assert set(np.unique(sim["measurements"][:, 1])) == set(range(10, 19))
    res = roitrack.track(camera, target, sim["measurements"])
    assert roitrack.evaluate(sim, res)["position_rmse_mm"] < 1.0


def test_evaluate_equals_roitrack_eval(orthoglide: Path, tmp_path: Path) -> None:
    poses, twists = tmp_path / "poses.tum", tmp_path / "twists.csv"
    run_cli("track", "--camera", orthoglide / "camera.yaml", "--target", orthoglide / "target.csv",
            "--measurements", orthoglide / "measurements.csv", "--poses", poses, "--twists", twists)
    expected = cli_json("eval", "--truth", orthoglide, "--poses", poses, "--twists", twists, "--json")
    sim = roitrack.simulate("orthoglide", seed=1)
    res = roitrack.track(sim["camera"], sim["target"], sim["measurements"])
    metrics = roitrack.evaluate(sim, res)
    assert metrics.keys() == expected.keys()
    for key, value in expected.items():
        if value is None or isinstance(value, str):
            # Absent figures (null) and names (the alignment) are equal, not close.
            assert metrics[key] == value, key
        else:
            np.testing.assert_allclose(metrics[key], value, rtol=1e-12, err_msg=key)
    # Without twists, no velocity figures (as `roitrack eval` without --twists).
    poses_only = {k: res[k] for k in ("t_s", "position_m", "quaternion_xyzw")}
    assert roitrack.evaluate(sim, poses_only)["velocity_rmse_mm_s"] is None


def write_pgm(path: Path, image: np.ndarray) -> None:
    path.write_bytes(f"P5\n{image.shape[1]} {image.shape[0]}\n255\n".encode() + image.astype(np.uint8).tobytes())


def photo_of(camera: roitrack.Camera, target: roitrack.Target, position_m: np.ndarray) -> np.ndarray:
    """Bright disks (anti-aliased by supersampling) where a fronto-parallel target at `position_m` images its points."""
    h, w = camera.height, camera.width
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    image = np.full((h, w), 20.0)
    for p, d in zip(target.points_m, target.diameters_m):
        x, y, z = p + position_m
        u, v, r = camera.fx * x / z + camera.cx, camera.fy * y / z + camera.cy, camera.fx * d / 2 / z
        near = (np.abs(xx - u) < r + 2) & (np.abs(yy - v) < r + 2)
        cover = np.zeros_like(image)
        for dy in np.linspace(-0.375, 0.375, 4):
            for dx in np.linspace(-0.375, 0.375, 4):
                cover += ((xx + dx - u) ** 2 + (yy + dy - v) ** 2 <= r * r) / 16
        image = np.where(near, image + 200 * cover, image)
    return np.clip(image, 0, 255).round()


def test_detect_equals_roitrack_detect(tmp_path: Path) -> None:
    run_cli("target", "--out", tmp_path / "target.csv", "--camera-out", tmp_path / "camera.yaml")
    camera = roitrack.Camera.from_yaml(tmp_path / "camera.yaml")
    target = roitrack.Target.from_csv(tmp_path / "target.csv")
    position = np.array([0.012, -0.007, 0.55])
    image = photo_of(camera, target, position)
    write_pgm(tmp_path / "photo.pgm", image)
    expected = cli_json("detect", "--camera", tmp_path / "camera.yaml", "--target", tmp_path / "target.csv",
                        "--json", tmp_path / "photo.pgm")
    assert expected["ok"]
    for array in (image.astype(np.uint8), ((image.astype(np.uint16) << 8) | image.astype(np.uint16)).astype(np.uint16)):
        det = roitrack.detect(camera, target, array, polarity="auto")
        assert det["ok"] and det["polarity"] == "bright"
        np.testing.assert_allclose(det["position_m"], position, atol=2e-4)
        if array.dtype == np.uint8:
            np.testing.assert_array_equal(det["ids"], [p["id"] for p in expected["points"]])
            np.testing.assert_allclose(det["uv_px"], [[p["u_px"], p["v_px"]] for p in expected["points"]], rtol=0, atol=1e-12)
            np.testing.assert_allclose(det["position_m"], expected["cam_t_obj_m"], rtol=0, atol=1e-12)
            np.testing.assert_allclose(det["quaternion_xyzw"], expected["cam_q_obj_xyzw"], rtol=0, atol=1e-12)
            assert det["residual_rms_px"] == pytest.approx(expected["residual_rms_px"], rel=1e-12)
            assert (det["ambiguous"], det["missing"], det["blobs"]) == (expected["ambiguous"], expected["missing"], expected["blobs"])
    # A blank image: not found, said so (as the command line's `ok: false`).
    blank = roitrack.detect(camera, target, np.zeros((camera.height, camera.width), np.uint8))
    assert not blank["ok"] and blank["error"] and blank["ids"].shape == (0,) and blank["uv_px"].shape == (0, 2)
