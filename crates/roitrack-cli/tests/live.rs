//! `roitrack live --fake` (feature `genicam`): the whole command through Aravis' fake GigE camera on 127.0.0.1, its
//! outputs read back, Ctrl-C, a pixel format the camera does not offer; `roitrack live --device`: an id refused
//! without `--allow-discovery`, an address where no camera answers failing fast; `roitrack bench --fake-camera`.
//! `roitrack live --fake --rig`: two fake cameras, the second on 127.0.0.2 in a network namespace of its own, one fused
//! track. Only one fake camera can own 127.0.0.1: the tests take turns (a lock here; CI also runs them on one test
//! thread).
#![cfg(all(feature = "genicam", unix))]

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::{Mutex, MutexGuard};
use std::time::{Duration, Instant};

#[path = "common/process.rs"]
mod process;
use process::{interrupt, roitrack_command as roitrack, simulate, succeeded};

static ONE_FAKE_CAMERA: Mutex<()> = Mutex::new(());

fn turn() -> MutexGuard<'static, ()> {
    ONE_FAKE_CAMERA.lock().unwrap_or_else(|e| e.into_inner())
}

/// `roitrack live --fake --duration SECONDS` writing its poses, twists and bag into `dir`; the command and those
/// three files.
fn live_fake(dir: &Path, seconds: &str) -> (Command, [PathBuf; 3]) {
    let files = ["p.tum", "t.csv", "live.mcap"].map(|name| dir.join(name));
    let mut command = roitrack();
    command
        .args(["live", "--fake", "--duration", seconds])
        .arg("--poses")
        .arg(&files[0])
        .arg("--twists")
        .arg(&files[1])
        .arg("--mcap")
        .arg(&files[2]);
    (command, files)
}

/// `roitrack eval --json` of `poses` and `twists` against the truth in `truth`: its metrics.
fn eval_json(truth: &Path, poses: &Path, twists: &Path) -> serde_json::Value {
    let eval = roitrack()
        .args(["eval", "--json", "--truth"])
        .arg(truth)
        .arg("--poses")
        .arg(poses)
        .arg("--twists")
        .arg(twists)
        .output()
        .unwrap();
    serde_json::from_str(&succeeded(eval)).unwrap()
}

#[test]
fn live_fake_writes_estimates_and_a_truth_that_eval_scores() {
    let _turn = turn();
    let dir = tempfile::tempdir().unwrap();
    let truth = dir.path().join("truth");
    let (mut live, [poses, twists, bag]) = live_fake(dir.path(), "1.5");
    let stdout = succeeded(live.arg("--truth-out").arg(&truth).output().unwrap());
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
    let metrics = eval_json(&truth, &poses, &twists);
    let rmse_mm = metrics["position_rmse_mm"].as_f64().unwrap();
    // The demo's default estimator on orthoglide: about 0.02 mm.
    assert!(rmse_mm < 0.1, "{metrics}");
}

#[test]
fn ctrl_c_stops_the_run_and_writes_every_output() {
    let _turn = turn();
    let dir = tempfile::tempdir().unwrap();
    // Aravis' fake camera on the loopback sometimes stalls for good after an incomplete first full frame (about 1
    // run in 3 on a 2-core machine: "ROIs grabbed 1, lost 1, incomplete 1", nothing more in 2.5 s). That stall is
    // tried once more, so that what this test checks (Ctrl-C stops the run and every output is written) is tested
    // on a camera that delivers; two stalls in a row fail.
    let mut attempt = 0;
    let (stdout, poses, twists, bag) = loop {
        attempt += 1;
        let (mut live, [poses, twists, bag]) = live_fake(dir.path(), "60");
        let child = live
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        std::thread::sleep(Duration::from_millis(2500));
        interrupt(&child);
        let start = Instant::now();
        let stdout = succeeded(child.wait_with_output().unwrap());
        assert!(start.elapsed() < Duration::from_secs(10));
        assert!(stdout.contains("stopped: interrupted (Ctrl-C)"), "{stdout}");
        let stalled = stdout.contains("ROIs grabbed 1, lost (no image in time) 1, incomplete 1");
        if stalled && attempt == 1 {
            eprintln!("the fake camera stalled after its first full frame; once more:\n{stdout}");
            continue;
        }
        break (stdout, poses, twists, bag);
    };
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

/// `roitrack live --device ADDRESS` on a simulated run's calibration and target, which must fail: its standard error
/// and how long it took.
fn live_device_fails(address: &str) -> (String, Duration) {
    let dir = tempfile::tempdir().unwrap();
    simulate(dir.path(), &["--scenario", "static"]);
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
    let took = start.elapsed();
    assert!(!out.status.success());
    (String::from_utf8_lossy(&out.stderr).into_owned(), took)
}

#[test]
fn a_device_id_is_refused_without_allow_discovery_and_nothing_is_sent() {
    let _turn = turn();
    let (stderr, took) = live_device_fails("Aravis-Fake-GV01");
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
    let (stderr, took) = live_device_fails("127.0.0.2");
    assert!(
        stderr
            .contains("cannot open the camera at '127.0.0.2': no GigE Vision camera answers there"),
        "{stderr}"
    );
    assert!(took < Duration::from_secs(15), "{took:?}");
}

/// `roitrack lab bench --fake-camera`: with the features `genicam` and `lab`.
#[cfg(feature = "lab")]
#[test]
fn bench_measures_the_fake_camera_rate_and_latency_from_buffer_timestamp_to_estimate() {
    let _turn = turn();
    let out = roitrack()
        .args([
            "lab",
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
    let m: serde_json::Value = serde_json::from_str(&succeeded(out)).unwrap();
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

/// The positions (t, x, y, z) of a TUM file.
fn tum_positions(path: &Path) -> Vec<[f64; 4]> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#') && !l.trim().is_empty())
        .map(|l| {
            let v: Vec<f64> = l.split_whitespace().map(|x| x.parse().unwrap()).collect();
            [v[0], v[1], v[2], v[3]]
        })
        .collect()
}

/// `roitrack servo --live --fake`: the closed loop in real time through Aravis' fake camera rendering the simulated
/// robot. Whether this shared machine holds the rate varies (docs/servo.md), so stability is not asserted here (the
/// simulated camera's run is, in roitrack-servo's tests/live.rs); what is: the run reports its figures, and the
/// tracker's estimates are where the robot was (the fake camera rendered the robot's pose, not a scenario's).
#[test]
fn servo_live_fake_renders_the_robot_and_reports_latency_and_error() {
    let _turn = turn();
    let dir = tempfile::tempdir().unwrap();
    let out = roitrack()
        .args([
            "servo",
            "--live",
            "--fake",
            "--rate-hz",
            "500",
            "--json",
            "--out",
        ])
        .arg(dir.path())
        .output()
        .unwrap();
    let line: serde_json::Value = serde_json::from_str(succeeded(out).trim()).unwrap();
    assert_eq!(line["camera"], "live-aravis-fake", "{line}");
    let f = |key: &str| {
        line[key]
            .as_f64()
            .unwrap_or_else(|| panic!("{key} in {line}"))
    };
    // On a loaded machine the fake camera serves a few dozen ROIs a second and the loop may diverge early: few.
    assert!(
        f("rois") >= 10.0 && f("estimates_published") >= 1.0,
        "{line}"
    );
    assert!(f("simulated_time_rms_error_mm") > 0.0, "{line}");
    assert!(
        f("exposure_to_actuation_us_p99") >= f("exposure_to_actuation_us_p50"),
        "{line}"
    );
    assert!(
        line["missed_ticks"].is_u64() && line["skipped_roi_slots"].is_u64(),
        "{line}"
    );
    assert!(
        line["stable"].as_bool().unwrap() || line["stop_reason"].is_string(),
        "{line}"
    );
    // Each estimate against the robot's true pose at the nearest control tick (both on the path's clock); before the
    // path's start (negative times) the robot was held at home, where the first tick finds it.
    let run = dir.path().join("ctc-live-aravis-fake");
    let achieved = tum_positions(&run.join("achieved.tum"));
    let estimates = tum_positions(&run.join("estimates.tum"));
    let mut errors_mm: Vec<f64> = estimates
        .iter()
        .filter_map(|e| {
            let i = achieved.partition_point(|a| a[0] < e[0]);
            let a = achieved.get(i)?;
            (e[0] < 0.0 || (a[0] - e[0]).abs() < 2e-3).then(|| {
                1e3 * ((a[1] - e[1]).powi(2) + (a[2] - e[2]).powi(2) + (a[3] - e[3]).powi(2)).sqrt()
            })
        })
        .collect();
    // At least one: under load a run may diverge after a handful of estimates (the few then say as much).
    assert!(
        !errors_mm.is_empty(),
        "{} estimates matched of {}",
        errors_mm.len(),
        estimates.len()
    );
    errors_mm.sort_by(f64::total_cmp);
    let median_mm = errors_mm[errors_mm.len() / 2];
    // The tracker sees the rendered robot to a few hundredths of a millimetre; within 2 ms of a tick at up to 1 m/s.
    assert!(
        median_mm < 1.0,
        "median {median_mm:.3} mm from the robot's pose"
    );
}

/// Set by CI, where the tests run as root: the rig of fake cameras, which needs a network namespace of its own, must
/// run, not be skipped.
const REQUIRE_NETNS: &str = "ROITRACK_REQUIRE_NETNS";

/// Runs `command` in a network namespace of its own whose loopback is up and also holds 127.0.0.2 (a second fake
/// camera's address), or `None` where namespaces are not permitted (skipped, unless [`REQUIRE_NETNS`] is set).
fn in_namespace_with_two_loopback_addresses(command: &Command) -> Option<std::process::Output> {
    let permitted = Command::new("unshare")
        .args(["-n", "true"])
        .status()
        .is_ok_and(|s| s.success());
    if !permitted {
        assert!(
            std::env::var_os(REQUIRE_NETNS).is_none(),
            "`unshare -n` is not permitted here, but {REQUIRE_NETNS} is set: the rig of fake cameras must run"
        );
        eprintln!(
            "skipped: `unshare -n` is not permitted here (a second fake camera needs 127.0.0.2 on lo)"
        );
        return None;
    }
    let mut script =
        String::from("ip link set lo up && ip addr add 127.0.0.2/8 dev lo || exit 90\nexec");
    for word in std::iter::once(command.get_program()).chain(command.get_args()) {
        script.push(' ');
        script.push_str(&format!(
            "'{}'",
            word.to_str().unwrap().replace('\'', r"'\''")
        ));
    }
    Some(
        Command::new("unshare")
            .args(["-n", "bash", "-c", &script])
            .output()
            .unwrap(),
    )
}

#[test]
fn a_rig_of_two_fake_cameras_gives_one_fused_track_and_learns_the_second_clock() {
    let dir = tempfile::tempdir().unwrap();
    // The rig: two cameras around the built-in scene, the second's clock left out (simulate writes the rig file).
    let scene = dir.path().join("scene");
    simulate(
        &scene,
        &["--rig-cameras", "2", "--seed", "3", "--duration-s", "0.1"],
    );
    let (poses, twists, truth, learnt) = (
        dir.path().join("p.tum"),
        dir.path().join("t.csv"),
        dir.path().join("truth"),
        dir.path().join("learnt.yaml"),
    );
    // The default 32 px windows: each ROI is measured within the part the scheduler asked for, so that the oblique
    // camera's neighbouring blobs in the rest of its window do not get its ROIs refused.
    let mut live = roitrack();
    live.args([
        "live",
        "--fake",
        "--seed",
        "3",
        "--duration",
        "1.5",
        "--rig",
    ])
    .arg(scene.join("rig.yaml"))
    .arg("--poses")
    .arg(&poses)
    .arg("--twists")
    .arg(&twists)
    .arg("--truth-out")
    .arg(&truth)
    .arg("--rig-out")
    .arg(&learnt);
    let Some(out) = in_namespace_with_two_loopback_addresses(&live) else {
        return;
    };
    let stdout = succeeded(out);
    // Each camera through the protocol at its own address, started once and kept on the target.
    for (name, address) in [("cam0", "127.0.0.1"), ("cam1", "127.0.0.2")] {
        let line = stdout
            .lines()
            .find(|l| l.starts_with(&format!("{name}: ")))
            .unwrap_or_else(|| panic!("{stdout}"));
        assert!(line.contains(&format!("at {address}")), "{stdout}");
    }
    assert_eq!(
        stdout.matches("1 initialisations (0 failed)").count(),
        2,
        "{stdout}"
    );
    assert!(
        stdout.contains("fused tracks started 1, refused 0"),
        "{stdout}"
    );
    // The fused track against the truth in the rig's frame, on the rig's clock.
    let metrics = eval_json(&truth, &poses, &twists);
    // About 0.01 mm on this rig (each camera alone about 0.025 mm).
    assert!(
        metrics["position_rmse_mm"].as_f64().unwrap() < 0.05,
        "{metrics}"
    );
    // The second camera's clock, drawn within ±50 ms, learnt to within a millisecond, with its uncertainty written.
    let options = Default::default();
    let learnt = roitrack::formats::read_rig_yaml(&learnt, &options).unwrap();
    let drawn = roitrack::formats::read_rig_yaml(truth.join("rig_truth.yaml"), &options).unwrap();
    let (learnt_clock, drawn_clock) = (learnt.rig.cameras()[1].clock, drawn.rig.cameras()[1].clock);
    assert!(drawn_clock.offset_s.abs() > 1e-3, "{drawn_clock:?}");
    assert!(
        (learnt_clock.offset_s - drawn_clock.offset_s).abs() < 1e-3,
        "{learnt_clock:?} {drawn_clock:?}"
    );
    let text = std::fs::read_to_string(dir.path().join("learnt.yaml")).unwrap();
    assert!(
        text.contains("clock_offset_sigma_s") && text.contains("clock_drift_sigma_ppm"),
        "{text}"
    );
}

#[test]
fn a_rig_refuses_a_device_of_no_camera_and_a_camera_without_one_naming_both() {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene");
    simulate(
        &scene,
        &["--rig-cameras", "2", "--seed", "1", "--duration-s", "0.1"],
    );
    let rig = scene.join("rig.yaml");
    let run = |devices: &[&str]| {
        let mut command = roitrack();
        command
            .args(["live", "--rig"])
            .arg(&rig)
            .arg("--target")
            .arg(scene.join("target.csv"));
        for device in devices {
            command.args(["--device", device]);
        }
        let out = command
            .args(["--poses", "p.tum", "--twists", "t.csv"])
            .current_dir(dir.path())
            .output()
            .unwrap();
        assert!(!out.status.success());
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let rig_name = rig.display().to_string();
    let stderr = run(&["cam0=192.0.2.1", "left=192.0.2.2"]);
    assert!(
        stderr.contains(&rig_name)
            && stderr.contains("no camera 'left'")
            && stderr.contains("cam0, cam1"),
        "{stderr}"
    );
    let stderr = run(&["cam0=192.0.2.1"]);
    assert!(
        stderr.contains("camera 'cam1'") && stderr.contains("--device cam1=ADDRESS"),
        "{stderr}"
    );
    let stderr = run(&["192.0.2.1"]);
    assert!(stderr.contains("NAME=ADDRESS"), "{stderr}");
    let stderr = run(&["cam0=192.0.2.1", "cam0=192.0.2.2", "cam1=192.0.2.3"]);
    assert!(stderr.contains("'cam0' given twice"), "{stderr}");
}

#[test]
fn a_second_fake_camera_without_its_loopback_address_is_refused_saying_how_to_add_it() {
    let has_second_address = Command::new("ip")
        .args(["-4", "addr", "show", "lo"])
        .output()
        .is_ok_and(|o| String::from_utf8_lossy(&o.stdout).contains("127.0.0.2"));
    if has_second_address {
        eprintln!("skipped: this host's loopback has 127.0.0.2");
        return;
    }
    let _turn = turn();
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene");
    simulate(
        &scene,
        &["--rig-cameras", "2", "--seed", "1", "--duration-s", "0.1"],
    );
    let out = roitrack()
        .args(["live", "--fake", "--duration", "0.2", "--rig"])
        .arg(scene.join("rig.yaml"))
        .args(["--poses", "p.tum", "--twists", "t.csv"])
        .current_dir(dir.path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(
        stderr.contains("camera 'cam1'")
            && stderr.contains("127.0.0.2")
            && stderr.contains("ip addr add"),
        "{stderr}"
    );
}
