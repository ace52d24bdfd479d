//! `roitrack live --fake` (feature `genicam`): the whole command through Aravis' fake GigE camera on 127.0.0.1, its
//! outputs read back, Ctrl-C, a pixel format the camera does not offer; `roitrack live --device`: an id refused
//! without `--allow-discovery`, an address where no camera answers failing fast; `roitrack bench --fake-camera`.
//! Only one fake camera can own 127.0.0.1: the tests take turns (a lock here; CI also runs them on one test thread).
#![cfg(all(feature = "genicam", unix))]

use std::process::{Command, Stdio};
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

static ONE_FAKE_CAMERA: Mutex<()> = Mutex::new(());

fn turn() -> MutexGuard<'static, ()> {
    ONE_FAKE_CAMERA.lock().unwrap_or_else(|e| e.into_inner())
}

fn roitrack() -> Command {
    Command::new(env!("CARGO_BIN_EXE_roitrack"))
}

#[test]
fn live_fake_writes_estimates_and_a_truth_that_eval_scores() {
    let _turn = turn();
    let dir = tempfile::tempdir().unwrap();
    let (poses, twists, truth, bag) = (
        dir.path().join("p.tum"),
        dir.path().join("t.csv"),
        dir.path().join("truth"),
        dir.path().join("live.mcap"),
    );
    let out = roitrack()
        .args(["live", "--fake", "--duration", "1.5", "--truth-out"])
        .arg(&truth)
        .arg("--poses")
        .arg(&poses)
        .arg("--twists")
        .arg(&twists)
        .arg("--mcap")
        .arg(&bag)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(stdout.contains("moved as asked 100.00 %"), "{stdout}");
    assert!(
        stdout.contains("latency from buffer timestamp to estimate p50/p99"),
        "{stdout}"
    );
    assert!(truth.join("gt_poses.tum").is_file() && truth.join("gt_twists.csv").is_file());
    // The estimates also as a ROS 2 bag (MCAP, completed: its magic at both ends).
    let bytes = std::fs::read(&bag).unwrap();
    assert!(
        bytes.starts_with(b"\x89MCAP0\r\n") && bytes.ends_with(b"\x89MCAP0\r\n"),
        "{} bytes",
        bytes.len()
    );
    // With the centroids the tracker used (their channel is in the bag's summary).
    assert!(
        bytes
            .windows(b"/roitrack/measurements".len())
            .any(|w| w == b"/roitrack/measurements")
    );
    let eval = roitrack()
        .args(["eval", "--json", "--truth"])
        .arg(&truth)
        .arg("--poses")
        .arg(&poses)
        .arg("--twists")
        .arg(&twists)
        .output()
        .unwrap();
    assert!(
        eval.status.success(),
        "{}",
        String::from_utf8_lossy(&eval.stderr)
    );
    let metrics: serde_json::Value = serde_json::from_slice(&eval.stdout).unwrap();
    let rmse_mm = metrics["position_rmse_mm"].as_f64().unwrap();
    // The demo's default estimator on orthoglide: about 0.02 mm.
    assert!(rmse_mm < 0.1, "{metrics}");
}

#[test]
fn ctrl_c_stops_the_run_and_writes_every_output() {
    let _turn = turn();
    let dir = tempfile::tempdir().unwrap();
    let (poses, twists, bag) = (
        dir.path().join("p.tum"),
        dir.path().join("t.csv"),
        dir.path().join("live.mcap"),
    );
    let child = roitrack()
        .args(["live", "--fake", "--duration", "60", "--poses"])
        .arg(&poses)
        .arg("--twists")
        .arg(&twists)
        .arg("--mcap")
        .arg(&bag)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(2500));
    // SAFETY: sends SIGINT to the child we spawned.
    assert_eq!(
        unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) },
        0
    );
    let start = Instant::now();
    let out = child.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(start.elapsed() < Duration::from_secs(10));
    assert!(stdout.contains("stopped: interrupted (Ctrl-C)"), "{stdout}");
    let rows = std::fs::read_to_string(&poses).unwrap().lines().count();
    assert!(rows > 10, "{rows} poses\n{stdout}");
    assert_eq!(
        std::fs::read_to_string(&twists).unwrap().lines().count(),
        rows + 1
    );
    assert!(
        std::fs::read(&bag).unwrap().ends_with(b"\x89MCAP0\r\n"),
        "the bag is not completed"
    );
}

#[test]
fn a_pixel_format_the_fake_camera_does_not_offer_is_refused_listing_those_it_does() {
    let _turn = turn();
    let dir = tempfile::tempdir().unwrap();
    let out = roitrack()
        .args([
            "live",
            "--fake",
            "--duration",
            "0.5",
            "--pixel-format",
            "mono12p",
        ])
        .arg("--poses")
        .arg(dir.path().join("p.tum"))
        .arg("--twists")
        .arg(dir.path().join("t.csv"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("Mono12p is not offered; the camera offers")
            && stderr.contains("Mono8")
            && stderr.contains("Mono16"),
        "{stderr}"
    );
}

/// `roitrack live --device ADDRESS` on a simulated run's calibration and target; its output and how long it took.
fn live_device(address: &str) -> (std::process::Output, Duration) {
    let dir = tempfile::tempdir().unwrap();
    let sim = roitrack()
        .args(["simulate", "--scenario", "static", "--out"])
        .arg(dir.path())
        .output()
        .unwrap();
    assert!(
        sim.status.success(),
        "{}",
        String::from_utf8_lossy(&sim.stderr)
    );
    let start = Instant::now();
    let out = roitrack()
        .args(["live", "--device", address, "--duration", "1", "--camera"])
        .arg(dir.path().join("camera.yaml"))
        .arg("--target")
        .arg(dir.path().join("target.csv"))
        .arg("--poses")
        .arg(dir.path().join("p.tum"))
        .arg("--twists")
        .arg(dir.path().join("t.csv"))
        .output()
        .unwrap();
    (out, start.elapsed())
}

#[test]
fn a_device_id_is_refused_without_allow_discovery_and_nothing_is_sent() {
    let _turn = turn();
    let (out, took) = live_device("Aravis-Fake-GV01");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr.contains("'Aravis-Fake-GV01'") && stderr.contains("--allow-discovery"),
        "{stderr}"
    );
    assert!(took < Duration::from_secs(5), "{took:?}");
}

#[test]
fn a_device_address_where_no_camera_answers_fails_fast_with_a_clear_error() {
    let _turn = turn();
    // No fake camera runs: nothing answers on 127.0.0.2.
    let (out, took) = live_device("127.0.0.2");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success());
    assert!(
        stderr
            .contains("cannot open the camera at '127.0.0.2': no GigE Vision camera answers there"),
        "{stderr}"
    );
    assert!(took < Duration::from_secs(15), "{took:?}");
}

#[test]
fn bench_measures_the_fake_camera_rate_and_latency_from_buffer_timestamp_to_estimate() {
    let _turn = turn();
    let out = roitrack()
        .args([
            "bench",
            "--json",
            "--rois",
            "2000",
            "--repeats",
            "1",
            "--item-ms",
            "10",
            "--fake-camera",
            "1",
        ])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let m: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let f = |key: &str| m[key].as_f64().unwrap_or_else(|| panic!("{key} in {m}"));
    assert!(f("fake_camera_rois") >= 3600.0, "{m}");
    for key in [
        "fake_camera_rois_per_s",
        "fake_camera_latency_us_p50",
        "fake_camera_grab_us_p50",
    ] {
        assert!(f(key) > 0.0, "{key} in {m}");
    }
    assert!(f("fake_camera_latency_us_p99") >= f("fake_camera_latency_us_p50"));
    assert!(f("fake_camera_moved_fraction") >= 0.95, "{m}");
}
