"""Every error path raises: files with the command line's messages (file, line, field), arrays of the wrong shape
(ValueError) or dtype (TypeError) naming the argument, invalid options, refused measurements."""

from pathlib import Path

import numpy as np
import pytest

import roitrack
from conftest import cli_error, read_measurements

GRID = np.array([[x, y, 0.0] for y in (-0.03, -0.01, 0.01, 0.03) for x in (-0.03, -0.01, 0.01, 0.03)])


@pytest.fixture(scope="module")
def sim() -> dict:
    return roitrack.simulate("orthoglide", seed=1)


def test_missing_files_raise_os_errors(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match="nope.yaml"):
        roitrack.Camera.from_yaml(tmp_path / "nope.yaml")
    with pytest.raises(FileNotFoundError, match="nope.csv"):
        roitrack.Target.from_csv(tmp_path / "nope.csv")
    with pytest.raises(roitrack.RoitrackError, match="is a folder"):
        roitrack.Camera.from_yaml(tmp_path)


@pytest.mark.parametrize(
    "old,new",
    [
        ("data: [1500.0, 0.0, 512.0", "data: [abc, 0.0, 512.0"),
        ("distortion_model: plumb_bob", "distortion_model: rational_polynomial"),
        ("image_width: 1024", "image_width: -3"),
        ("image_height: 1024\n", ""),
    ],
)
def test_bad_camera_file_has_the_command_line_message(orthoglide: Path, tmp_path: Path, old: str, new: str) -> None:
    text = (orthoglide / "camera.yaml").read_text()
    assert old in text
    bad = tmp_path / "camera.yaml"
    bad.write_text(text.replace(old, new, 1))
    expected = cli_error("track", "--camera", bad, "--target", orthoglide / "target.csv", "--measurements",
                         orthoglide / "measurements.csv", "--poses", tmp_path / "p.tum", "--twists", tmp_path / "t.csv")
    assert str(bad) in expected
    with pytest.raises(roitrack.RoitrackError) as raised:
        roitrack.Camera.from_yaml(bad)
    assert str(raised.value) == expected
    assert isinstance(raised.value, ValueError)


@pytest.mark.parametrize(
    "line,expected_part",
    [("3,0.01,-0.03,0,0.006\n3,0.03,-0.03,0,0.006", "id"), ("2,0.01,abc,0,0.006", "'y'"), ("2,0.01", "")],
)
def test_bad_target_file_has_the_command_line_message(orthoglide: Path, tmp_path: Path, line: str, expected_part: str) -> None:
    lines = (orthoglide / "target.csv").read_text().splitlines()
    lines[3] = line
    bad = tmp_path / "target.csv"
    bad.write_text("\n".join(lines) + "\n")
    expected = cli_error("track", "--camera", orthoglide / "camera.yaml", "--target", bad, "--measurements",
                         orthoglide / "measurements.csv", "--poses", tmp_path / "p.tum", "--twists", tmp_path / "t.csv")
    assert str(bad) in expected and expected_part in expected
    with pytest.raises(roitrack.RoitrackError) as raised:
        roitrack.Target.from_csv(bad)
    assert str(raised.value) == expected


def test_camera_constructor_refuses_bad_values() -> None:
    with pytest.raises(roitrack.RoitrackError, match="fx must be positive"):
        roitrack.Camera(640, 480, -1.0, 500.0, 320.0, 240.0)
    with pytest.raises(roitrack.RoitrackError, match="cy must be a finite number"):
        roitrack.Camera(640, 480, 500.0, 500.0, 320.0, float("nan"))
    with pytest.raises(roitrack.RoitrackError, match="image size"):
        roitrack.Camera(0, 480, 500.0, 500.0, 320.0, 240.0)
    with pytest.raises(ValueError, match="distortion: plumb_bob takes 4 or 5 numbers"):
        roitrack.Camera(640, 480, 500.0, 500.0, 320.0, 240.0, distortion=[0.1, 0.2])
    with pytest.raises(ValueError, match="distortion: equidistant takes 4 numbers"):
        roitrack.Camera(640, 480, 500.0, 500.0, 320.0, 240.0, distortion=[0.1] * 5, model="equidistant")
    with pytest.raises(ValueError, match="distortion: .*kannala"):
        roitrack.Camera(640, 480, 500.0, 500.0, 320.0, 240.0, distortion=[0.1] * 4, model="kannala")
    with pytest.raises(ValueError, match="distortion: coefficient 1 must be a finite number"):
        roitrack.Camera(640, 480, 500.0, 500.0, 320.0, 240.0, distortion=[0.1, float("inf"), 0, 0])
    with pytest.raises(TypeError):
        roitrack.Camera(640, 480, "fx", 500.0, 320.0, 240.0)  # type: ignore[arg-type]
    # Values no camera has, refused by the library's checks as the command line's files are.
    with pytest.raises(roitrack.RoitrackError, match="fx = 1e-300 px is not a camera's"):
        roitrack.Camera(640, 480, 1e-300, 500.0, 320.0, 240.0)
    with pytest.raises(roitrack.RoitrackError, match="k1 = 1000000: the plumb_bob lens model scales"):
        roitrack.Camera(640, 480, 500.0, 500.0, 320.0, 240.0, distortion=[1e6, 0.0, 0.0, 0.0])
    # Tangential terms of 0.1 fold this rational lens back inside the image.
    with pytest.raises(roitrack.RoitrackError, match="folds back"):
        roitrack.Camera(640, 480, 500.0, 500.0, 320.0, 240.0, distortion=[0.1] * 8, model="rational_polynomial")


def test_target_constructor_refuses_bad_arrays() -> None:
    with pytest.raises(TypeError, match="points_m: expected a float64 array, got dtype float32"):
        roitrack.Target(GRID.astype(np.float32))
    with pytest.raises(ValueError, match=r"points_m: expected an array of shape \(N, 3\), got shape \[16, 2\]"):
        roitrack.Target(GRID[:, :2].copy())
    with pytest.raises(ValueError, match="points_m: expected an array of shape"):
        roitrack.Target(GRID.ravel())
    with pytest.raises(TypeError, match="points_m"):
        roitrack.Target([["a", "b", "c"]] * 4)
    with pytest.raises(ValueError, match="ids: expected 16 ids"):
        roitrack.Target(GRID, ids=[1, 2, 3])
    with pytest.raises(ValueError, match="diameters_m: expected 16 diameters"):
        roitrack.Target(GRID, diameters_m=[0.006])
    with pytest.raises((TypeError, OverflowError), match="ids"):
        roitrack.Target(GRID, ids=[-1] * 16)
    with pytest.raises(roitrack.RoitrackError):
        roitrack.Target(GRID, ids=[0] * 16)  # duplicate ids
    with pytest.raises(roitrack.RoitrackError):
        roitrack.Target(GRID[:3].copy())  # too few points
    with pytest.raises(roitrack.RoitrackError):
        roitrack.Target(np.array([[0.01 * k, 0, 0] for k in range(5)]))  # collinear
    with pytest.raises(ValueError, match="units: unknown value 'inch'"):
        roitrack.Target.from_csv("target.csv", units="inch")
    # A list converts.
    assert len(roitrack.Target(GRID.tolist())) == 16


def test_tracker_refuses_bad_options(sim: dict) -> None:
    cam, tgt = sim["camera"], sim["target"]
    with pytest.raises(ValueError, match="estimator: unknown value 'ekf' .*kalman, exact, paper, static, batch"):
        roitrack.Tracker(cam, tgt, estimator="ekf")
    with pytest.raises(ValueError, match="adapt: unknown value"):
        roitrack.Tracker(cam, tgt, adapt="always")
    with pytest.raises(ValueError, match="robust: unknown value"):
        roitrack.Tracker(cam, tgt, robust="cauchy")
    with pytest.raises(ValueError, match="motion-model: unknown value 'jerk' .*constant-velocity, constant-acceleration"):
        roitrack.Tracker(cam, tgt, motion_model="jerk")
    with pytest.raises(roitrack.RoitrackError, match="linear_jerk_psd must be from"):
        roitrack.Tracker(cam, tgt, jerk_psd=-1.0)
    with pytest.raises(ValueError, match="jerk-psd does not apply to the constant-velocity motion model"):
        roitrack.Tracker(cam, tgt, motion_model="constant-velocity", jerk_psd=5.0)
    with pytest.raises(roitrack.RoitrackError, match="invalid tracker options: every must be at least 1"):
        roitrack.Tracker(cam, tgt, every=0)
    with pytest.raises(roitrack.RoitrackError, match="noise_px must be positive"):
        roitrack.Tracker(cam, tgt, noise_px=-0.1)
    with pytest.raises(roitrack.RoitrackError, match="gain"):
        roitrack.Tracker(cam, tgt, estimator="paper", gain=3.0)
    with pytest.raises(roitrack.RoitrackError, match="window"):
        roitrack.Tracker(cam, tgt, window=2)
    with pytest.raises(OverflowError):
        roitrack.Tracker(cam, tgt, every=-1)
    with pytest.raises(TypeError):
        roitrack.Tracker(cam, cam)  # type: ignore[arg-type]


def test_push_refuses_bad_measurements_and_keeps_its_state(sim: dict) -> None:
    tracker = roitrack.Tracker(sim["camera"], sim["target"])
    rows = sim["measurements"]
    for t, i, u, v in rows[:100]:
        tracker.push(t, int(i), u, v)
    with pytest.raises(roitrack.RoitrackError, match="point id 99 is not in the target"):
        tracker.push(rows[100, 0], 99, 1.0, 1.0)
    with pytest.raises(roitrack.RoitrackError, match="older than the previous one"):
        tracker.push(0.0, 0, 500.0, 500.0)
    with pytest.raises(roitrack.RoitrackError, match="u is not finite"):
        tracker.push(rows[100, 0], 0, float("nan"), 500.0)
    with pytest.raises(OverflowError):
        tracker.push(rows[100, 0], -1, 500.0, 500.0)
    with pytest.raises(TypeError):
        tracker.push("now", 0, 500.0, 500.0)  # type: ignore[arg-type]
    assert tracker.measurements == 100
    estimates = [tracker.push(t, int(i), u, v) for t, i, u, v in rows[100:2000]]
    assert any(e is not None and e.status == "tracking" for e in estimates)


def test_track_refuses_bad_arrays(sim: dict) -> None:
    cam, tgt, rows = sim["camera"], sim["target"], sim["measurements"]
    with pytest.raises(TypeError, match="measurements: expected a float64 array, got dtype float32"):
        roitrack.track(cam, tgt, rows.astype(np.float32))
    with pytest.raises(TypeError, match="measurements: expected a float64 array, got dtype int64"):
        roitrack.track(cam, tgt, rows.astype(np.int64))
    with pytest.raises(ValueError, match=r"measurements: expected an array of shape \(N, 4\), got shape \[19655, 3\]"):
        roitrack.track(cam, tgt, rows[:, :3])
    with pytest.raises(ValueError, match=r"measurements: expected an array of shape \(N, 4\)"):
        roitrack.track(cam, tgt, rows.ravel())
    bad = rows.copy()
    bad[7, 1] = 2.5
    with pytest.raises(ValueError, match=r"measurements: row 7, column 1 \(id\): 2.5 is not a point id"):
        roitrack.track(cam, tgt, bad)
    bad[7, 1] = -1
    with pytest.raises(ValueError, match="row 7"):
        roitrack.track(cam, tgt, bad)
    bad[7, 1] = 99
    with pytest.raises(roitrack.RoitrackError, match="measurement 7: .*point id 99 is not in the target"):
        roitrack.track(cam, tgt, bad)
    bad = rows.copy()
    bad[9, 0] = 0.0
    with pytest.raises(roitrack.RoitrackError, match="measurement 9: .*older than the previous one"):
        roitrack.track(cam, tgt, bad)
    with pytest.raises(roitrack.RoitrackError, match="no estimate from 5 measurements"):
        roitrack.track(cam, tgt, rows[:5])
    with pytest.raises(ValueError, match="estimator: unknown value"):
        roitrack.track(cam, tgt, rows, estimator="nope")
    # Strided and Fortran-ordered views are read correctly.
    wide = np.zeros((len(rows), 8))
    wide[:, ::2] = rows
    res = roitrack.track(cam, tgt, wide[:, ::2])
    assert np.array_equal(res["position_m"], roitrack.track(cam, tgt, np.asfortranarray(rows))["position_m"])


def test_detect_refuses_bad_images(sim: dict) -> None:
    cam, tgt = sim["camera"], sim["target"]
    image = np.zeros((cam.height, cam.width), np.uint8)
    with pytest.raises(TypeError, match="image: expected dtype uint8 or uint16, got float64"):
        roitrack.detect(cam, tgt, image.astype(np.float64))
    with pytest.raises(TypeError, match="image: expected a numpy array"):
        roitrack.detect(cam, tgt, image.tolist())  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"image: expected an array of shape \(H, W\), got shape \[1024, 1024, 3\]"):
        roitrack.detect(cam, tgt, np.zeros((cam.height, cam.width, 3), np.uint8))
    with pytest.raises(ValueError, match="image: the image is 640 x 480 px, the camera's 1024 x 1024 px"):
        roitrack.detect(cam, tgt, np.zeros((480, 640), np.uint8))
    with pytest.raises(ValueError, match="polarity: unknown value 'grey'"):
        roitrack.detect(cam, tgt, image, polarity="grey")
    with pytest.raises(ValueError, match="distance_m"):
        roitrack.detect(cam, tgt, image, distance_m=(1.0, 0.5))


def test_simulate_refuses_bad_options() -> None:
    with pytest.raises(ValueError, match="scenario: unknown value 'circle'"):
        roitrack.simulate("circle")
    with pytest.raises(ValueError, match="order: unknown value"):
        roitrack.simulate("static", order="zigzag")
    with pytest.raises(roitrack.RoitrackError, match="noise_px must be finite and >= 0"):
        roitrack.simulate("static", noise_px=-1.0)
    with pytest.raises(roitrack.RoitrackError, match="rate_hz must be positive"):
        roitrack.simulate("static", rate_hz=0.0)
    with pytest.raises(roitrack.RoitrackError, match="drop_fraction"):
        roitrack.simulate("static", drop=1.0)
    tiny = roitrack.Camera(64, 64, 5000.0, 5000.0, 32.0, 32.0)
    with pytest.raises(roitrack.RoitrackError, match="leaves the image"):
        roitrack.simulate("orthoglide", camera=tiny)


def test_evaluate_refuses_bad_dicts(sim: dict) -> None:
    res = roitrack.track(sim["camera"], sim["target"], sim["measurements"])
    with pytest.raises(KeyError, match="res: missing key 'position_m'"):
        roitrack.evaluate(sim, {"t_s": res["t_s"]})
    with pytest.raises(KeyError, match="sim: missing key 'gt_t_s'"):
        roitrack.evaluate({}, res)
    short = dict(res, position_m=res["position_m"][:-1])
    with pytest.raises(ValueError, match=r"res\['position_m'\]: expected \d+ rows"):
        roitrack.evaluate(sim, short)
    with pytest.raises(ValueError, match=r"res\['quaternion_xyzw'\]: expected an array of shape \(N, 4\)"):
        roitrack.evaluate(sim, dict(res, quaternion_xyzw=res["quaternion_xyzw"][:, :3]))
    with pytest.raises(TypeError, match=r"res\['position_m'\]: expected a float64 array"):
        roitrack.evaluate(sim, dict(res, position_m=res["position_m"].astype(np.float32)))
    late = dict(res, t_s=res["t_s"] + 100.0)
    with pytest.raises(roitrack.RoitrackError):
        roitrack.evaluate(sim, late)
    with pytest.raises(TypeError):
        roitrack.evaluate(sim, [1, 2])  # type: ignore[arg-type]


def test_measurements_file_read_by_numpy_round_trips(orthoglide: Path, sim: dict) -> None:
    assert np.array_equal(read_measurements(orthoglide / "measurements.csv"), sim["measurements"])


def test_target_in_millimetres_as_the_command_line(orthoglide: Path, tmp_path: Path) -> None:
    """A target file in millimetres is refused with the command line's message unless its unit is said."""
    target = roitrack.Target.from_csv(orthoglide / "target.csv")
    lines = ["id,x,y,z,diameter"] + [
        f"{i},{1e3 * x},{1e3 * y},{1e3 * z},{1e3 * d}" for i, (x, y, z), d in zip(target.ids, target.points_m, target.diameters_m)
    ]
    mm = tmp_path / "target_mm.csv"
    mm.write_text("\n".join(lines) + "\n")
    args = ["track", "--camera", orthoglide / "camera.yaml", "--measurements", orthoglide / "measurements.csv",
            "--poses", tmp_path / "p.tum", "--twists", tmp_path / "t.csv", "--target", mm]
    expected = cli_error(*args)
    assert "--target-units mm" in expected
    with pytest.raises(roitrack.RoitrackError) as raised:
        roitrack.Target.from_csv(mm)
    assert str(raised.value) == expected
    np.testing.assert_allclose(roitrack.Target.from_csv(mm, units="mm").points_m, target.points_m, rtol=1e-12)


def test_camera_models(tmp_path: Path) -> None:
    fisheye = roitrack.Camera(640, 480, 300.0, 300.0, 320.0, 240.0, distortion=[0.05, -0.01, 0.0, 0.0], model="equidistant")
    assert (fisheye.model, fisheye.distortion) == ("equidistant", [0.05, -0.01, 0.0, 0.0])
    rational = roitrack.Camera(640, 480, 500.0, 500.0, 320.0, 240.0, distortion=[0.1, 0.01, 1e-3, -1e-3, 0.0, 0.1, 0.01, 0.0],
                               model="rational_polynomial")
    assert rational.model == "rational_polynomial" and len(rational.distortion) == 8
    assert roitrack.Camera(640, 480, 500.0, 500.0, 320.0, 240.0).model == "none"
    four = roitrack.Camera(640, 480, 500.0, 500.0, 320.0, 240.0, distortion=[0.1, 0.01, 0.0, 0.0])
    assert (four.model, four.distortion) == ("plumb_bob", [0.1, 0.01, 0.0, 0.0, 0.0])
    four.to_yaml(tmp_path / "camera.yaml")
    again = roitrack.Camera.from_file(tmp_path / "camera.yaml")
    assert (again.model, again.distortion, again.fx) == (four.model, four.distortion, four.fx)
