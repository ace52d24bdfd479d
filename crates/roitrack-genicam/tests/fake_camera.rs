//! The live loop through Aravis' fake GigE Vision camera on 127.0.0.1 (feature `genicam`): tracking as well as the
//! demo's simulated camera (Mono8 and Mono16, software trigger and free run), the window moved as asked, the clock
//! offset and the latency from buffer timestamp to estimate, a clean stop, a camera that disappears, lost packets,
//! pixel formats the camera does not offer, addresses that are not a camera's. Only one fake camera can own
//! 127.0.0.1: the tests take turns (a lock here; CI also runs them on one test thread).
#![cfg(feature = "genicam")]

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::{Duration, Instant};

use roitrack_demo::{Demo, DemoOptions, lineup};
use roitrack_estimators::Estimate;
use roitrack_genicam::{
    FAKE_DEVICE_CLOCK_START_S, FakeGigeCamera, GenicamCamera, GenicamError, GenicamOptions,
    LiveOptions, LiveReport, PixelFormatChoice, TriggerChoice, run_fake,
};
use roitrack_image::{Frame, GrabError, Roi, RoiCamera, RoiImage, RoiTrigger};
use roitrack_sim::{Scenario, ScenarioKind};

static ONE_FAKE_CAMERA: Mutex<()> = Mutex::new(());

fn turn() -> MutexGuard<'static, ()> {
    ONE_FAKE_CAMERA.lock().unwrap_or_else(|e| e.into_inner())
}

/// Waits until the fake camera has served `count` buffers (at most 60 s: the run is then judged as it is).
fn wait_for_rois(fake: &FakeGigeCamera, count: usize) {
    let start = std::time::Instant::now();
    while fake.rendered().0 < count && start.elapsed() < Duration::from_secs(60) {
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Position RMSE (mm) of the vouched-for estimates up to `until_s`, against the scenario's truth.
fn position_rmse_mm(estimates: &[Estimate], scenario: &Scenario, until_s: f64) -> (f64, usize) {
    let errors: Vec<f64> = estimates
        .iter()
        .filter(|e| e.t_ref_s <= until_s && e.status.is_vouched_for())
        .map(|e| (e.state.cam_t_obj_m - scenario.state_at(e.t_ref_s).cam_t_obj_m).norm() * 1e3)
        .collect();
    let n = errors.len();
    (
        (errors.iter().map(|x| x * x).sum::<f64>() / n.max(1) as f64).sqrt(),
        n,
    )
}

/// Runs the fake camera on the demo's scenario for `duration_s` with `camera` options and checks the tracking
/// against the demo's default estimator on its simulated camera (position RMSE within 2x, as many estimates), no early
/// stop, the clock offset and the latencies; returns the report.
fn track_like_the_demo(camera: GenicamOptions, duration_s: f64) -> LiveReport {
    let demo = Demo::new(DemoOptions::default()).unwrap();
    let kalman = &lineup()[0];
    let reference = demo.from_images(kalman, None).unwrap();
    let scenario = &demo.scenario;
    let options = LiveOptions {
        camera,
        duration_s,
        rate_hz: demo.simulation.rate_hz,
        tracker: demo.config(kalman),
        keep_measurements: true,
    };
    // Each estimate is also handed over as it is made (the live view's hook): all of them, in order.
    let mut handed = Vec::new();
    let report = run_fake(
        scenario,
        &options,
        1,
        Arc::new(AtomicBool::new(false)),
        |_| {},
        &mut |e| handed.push(e.t_ref_s),
    )
    .unwrap();
    let t_ref_s: Vec<f64> = report
        .loop_report
        .estimates
        .iter()
        .map(|e| e.t_ref_s)
        .collect();
    assert_eq!(handed, t_ref_s);
    // Every measurement the estimator got is kept (for the bag), in time order, up to the last estimate.
    let measured = &report.loop_report.measured;
    assert!(measured.len() > 4 * t_ref_s.len(), "{}", measured.len());
    assert!(measured.windows(2).all(|m| m[0].t_s <= m[1].t_s));
    println!("{}", report.summary());
    let reference_estimates = &reference.loop_report.as_ref().unwrap().estimates;
    let (demo_mm, demo_n) = position_rmse_mm(reference_estimates, scenario, duration_s);
    let (fake_mm, fake_n) = position_rmse_mm(&report.loop_report.estimates, scenario, duration_s);
    println!(
        "position RMSE up to {duration_s} s: fake camera {fake_mm:.4} mm ({fake_n} estimates), demo {demo_mm:.4} mm ({demo_n})"
    );
    assert!(
        report.loop_report.acquisition.stopped_by.is_none(),
        "{:?}",
        report.loop_report.acquisition.stopped_by
    );
    assert!(
        fake_n as f64 > 0.8 * demo_n as f64,
        "{fake_n} estimates against the demo's {demo_n}"
    );
    assert!(
        fake_mm <= 2.0 * demo_mm,
        "fake camera {fake_mm:.4} mm, demo {demo_mm:.4} mm"
    );
    let camera = &report.camera;
    assert!(
        camera.rois as f64 >= 0.9 * duration_s * options.rate_hz,
        "{camera:?}"
    );
    // The fake camera's device clock runs with the host's from FAKE_DEVICE_CLOCK_START_S before the run: the
    // offset is that, plus the time from the camera's start to the first grab, less the smallest latency, and it
    // does not move.
    let offset_s = camera.clock_offset_s.unwrap();
    assert!(
        (FAKE_DEVICE_CLOCK_START_S - 0.01..FAKE_DEVICE_CLOCK_START_S + 5.0).contains(&offset_s),
        "offset {offset_s} s"
    );
    // The same clock on both sides: after its first block of buffers the estimate moves only with the smallest
    // latency (tens of microseconds on loopback, more on a loaded machine).
    let moved_s = camera.clock_change_s.unwrap();
    assert!(moved_s.abs() < 5e-3, "the offset moved {moved_s} s");
    // Below the true offset by the smallest arrival latency: positive, and under a grab's time.
    let below_s = report.true_clock_offset_s.unwrap() - offset_s;
    assert!(
        (0.0..2e-3).contains(&below_s),
        "{below_s} s below the true offset"
    );
    // One latency from buffer timestamp to estimate per estimate, each at least the time from the grab's return.
    let stamps = &report.timestamp_to_estimate_us;
    assert_eq!(stamps.len(), report.loop_report.estimates.len());
    assert!(
        stamps
            .iter()
            .zip(&report.loop_report.latencies_us)
            .all(|(stamp, grab)| stamp >= grab && stamp.is_finite()),
        "a timestamp-to-estimate latency below its grab-to-estimate one"
    );
    let (p50, p99) = report.timestamp_to_estimate_quantiles_us();
    assert!(p50 > 0.0 && p50 <= p99 && p99 < 1e6, "{p50} / {p99} us");
    report
}

#[test]
fn tracks_through_the_protocol_within_twice_the_demo_error_and_moves_the_window() {
    let _turn = turn();
    let report = track_like_the_demo(GenicamOptions::default(), 2.0);
    let camera = &report.camera;
    assert!(
        report.description.contains("Mono8"),
        "{}",
        report.description
    );
    assert!(
        camera.moved_fraction() >= 0.95,
        "moved as asked: {}",
        camera.moved_fraction()
    );
    assert!(
        camera.moves as f64 >= 0.95 * camera.rois as f64,
        "{} moves for {} ROIs",
        camera.moves,
        camera.rois
    );
    // Software trigger: each ROI exposed at the time asked, but for the late frame of a lost grab that a later ROI
    // of the same window takes (at its own time).
    assert!(camera.retimed <= camera.lost, "{camera:?}");
}

#[test]
fn tracks_at_mono16_as_well() {
    let _turn = turn();
    let camera = GenicamOptions {
        pixel_format: Some(PixelFormatChoice::Mono16),
        ..GenicamOptions::default()
    };
    let report = track_like_the_demo(camera, 2.0);
    assert!(
        report.description.contains("Mono16"),
        "{}",
        report.description
    );
    assert!(report.camera.moved_fraction() >= 0.95);
}

#[test]
fn tracks_in_free_run_each_roi_at_the_time_and_window_its_buffer_reports() {
    let _turn = turn();
    let camera = GenicamOptions {
        trigger: TriggerChoice::FreeRun,
        ..GenicamOptions::default()
    };
    // Free run is slower (frames from the old window are skipped, each ROI waits for a frame): 1 s of the scenario.
    let report = track_like_the_demo(camera, 1.0);
    assert!(
        report.description.contains("free run"),
        "{}",
        report.description
    );
    let camera = &report.camera;
    // The window still moves for (nearly) every ROI; the frames begun before the move are skipped as stale.
    assert!(
        camera.moves as f64 >= 0.95 * camera.rois as f64,
        "{camera:?}"
    );
}

/// The fake camera on the default scenario and a camera opened on it with `options` (address and serial filled in).
fn open_fake(
    options: GenicamOptions,
) -> (
    FakeGigeCamera,
    Result<GenicamCamera, GenicamError>,
    Scenario,
) {
    let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
    let fake = FakeGigeCamera::start(&scenario, Default::default(), 1).unwrap();
    let options = GenicamOptions {
        address: fake.address().to_string(),
        expected_serial: Some(fake.serial().to_string()),
        ..options
    };
    let full_size = (scenario.camera.width_px, scenario.camera.height_px);
    let camera = GenicamCamera::open(&options, full_size).map(|c| c.with_scene_clock(fake.clock()));
    (fake, camera, scenario)
}

#[test]
fn mono16_frames_carry_the_mono8_image_scaled_to_16_bits() {
    let _turn = turn();
    let mean_and_max = |format| {
        let (_fake, camera, _) = open_fake(GenicamOptions {
            pixel_format: Some(format),
            ..GenicamOptions::default()
        });
        let mut camera = camera.unwrap();
        assert_eq!(camera.pixel_format(), format);
        let mut frame = Frame::default();
        // A full frame (a burst of packets) may come incomplete on a loaded machine: the loop tries again, so
        // does this.
        let mut tries = 0;
        while let Err(e) = camera.grab_full_frame(0.5, &mut frame) {
            tries += 1;
            assert!(tries < 3, "{format}: {e}: {:?}", camera.stats());
        }
        let mean =
            frame.pixels.iter().map(|&v| f64::from(v)).sum::<f64>() / frame.pixels.len() as f64;
        (frame.bit_depth, mean, *frame.pixels.iter().max().unwrap())
    };
    let (depth8, mean8, max8) = mean_and_max(PixelFormatChoice::Mono8);
    let (depth16, mean16, max16) = mean_and_max(PixelFormatChoice::Mono16);
    assert_eq!((depth8, depth16), (8, 16));
    assert!(max8 <= 255 && max16 > 255, "{max8} {max16}");
    // The same scene at the same time (the noise differs): 256 times the values, within the noise's share.
    let ratio = mean16 / mean8;
    assert!((ratio - 256.0).abs() < 0.05 * 256.0, "{mean16} / {mean8}");
}

#[test]
fn a_pixel_format_the_camera_does_not_offer_is_refused_with_those_it_does() {
    let _turn = turn();
    for format in [PixelFormatChoice::Mono12, PixelFormatChoice::Mono12Packed] {
        let (_fake, camera, _) = open_fake(GenicamOptions {
            pixel_format: Some(format),
            ..GenicamOptions::default()
        });
        let message = camera.err().expect("refused").to_string();
        assert!(
            message.contains(&format!("{format} is not offered"))
                && message.contains("Mono8")
                && message.contains("Mono16"),
            "{message}"
        );
    }
}

#[test]
fn an_id_needs_discovery_allowed_and_an_address_without_a_camera_fails_fast() {
    let _turn = turn();
    let open = |address: &str| {
        let options = GenicamOptions {
            address: address.into(),
            ..GenicamOptions::default()
        };
        let start = Instant::now();
        let result = GenicamCamera::open(&options, (64, 64));
        (result.err().expect("refused").to_string(), start.elapsed())
    };
    // An id: refused at once, nothing sent.
    let (message, took) = open("Aravis-Fake-GV01");
    assert!(
        message.contains("--allow-discovery") && message.contains("not an IPv4 address"),
        "{message}"
    );
    assert!(took < Duration::from_millis(50), "{took:?}");
    for (address, says) in [
        ("127.0.0.1:4000", "port 3956"),
        ("255.255.255.255", "broadcast"),
        ("", "no address"),
    ] {
        let (message, _) = open(address);
        assert!(message.contains(says), "{address}: {message}");
    }
    // A loopback address where no camera answers (the fake camera is not running): an error naming it, in seconds,
    // with no discovery.
    let (message, took) = open("127.0.0.2");
    assert!(
        message.contains("'127.0.0.2'") && message.contains("no GigE Vision camera answers"),
        "{message}"
    );
    assert!(took < Duration::from_secs(10), "{took:?}");
    println!("no camera at 127.0.0.2: refused after {took:?}: {message}");
}

#[test]
fn lost_packets_make_incomplete_buffers_that_are_counted_and_survived() {
    let _turn = turn();
    // A receive buffer far smaller than a full frame's burst of packets and no resend: full frames lose packets.
    let (_fake, camera, scenario) = open_fake(GenicamOptions {
        socket_buffer_bytes: 4096,
        packet_resend: false,
        timeout_s: 0.1,
        ..GenicamOptions::default()
    });
    let mut camera = camera.unwrap();
    let mut frame = Frame::default();
    let mut failed = 0;
    for k in 0..3 {
        if let Err(e) = camera.grab_full_frame(0.1 * k as f64, &mut frame) {
            assert!(e.is_transient(), "{e}");
            failed += 1;
        }
    }
    let stats = camera.stats();
    println!("{stats:?}");
    assert!(failed >= 1, "every full frame arrived whole: {stats:?}");
    assert!(stats.incomplete + stats.driver_failures >= 1, "{stats:?}");
    // The camera goes on: ROIs (one packet each) still arrive.
    let mut image = RoiImage::with_capacity(32 * 32);
    let point = &scenario.target.points()[0];
    for k in 0..20 {
        let trigger = RoiTrigger {
            point_id: point.id,
            roi: Roi::new(100 + 4 * k, 200, 32, 32),
            t_s: 1.0 + k as f64 * 1e-3,
        };
        // A ROI may still be lost now and then on a loaded machine (0.1 s timeout): it is tried again.
        let mut tries = 0;
        while let Err(e) = camera.grab_roi(&trigger, &mut image) {
            tries += 1;
            assert!(e.is_transient() && tries < 3, "{e}: {:?}", camera.stats());
        }
        assert_eq!(image.roi, Roi::new(100 + 4 * k, 200, 32, 32));
        // The ROI's time is the one its buffer was exposed at: the trigger's, or, if a lost ROI's late frame was
        // begun after this window moved, that earlier ROI's (and counted).
        assert!(
            image.t_s == trigger.t_s || (image.t_s >= 1.0 && image.t_s < trigger.t_s),
            "{} for {}",
            image.t_s,
            trigger.t_s
        );
        assert!(image.t_s == trigger.t_s || camera.stats().retimed > 0);
    }
    assert_eq!(camera.stats().rois, 20);
}

#[test]
fn ctrl_c_stops_cleanly_with_the_estimates_so_far() {
    let _turn = turn();
    let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
    let stop = Arc::new(AtomicBool::new(false));
    let options = LiveOptions {
        duration_s: 60.0,
        ..LiveOptions::default()
    };
    let flag = stop.clone();
    let report = run_fake(
        &scenario,
        &options,
        1,
        stop,
        move |fake| {
            std::thread::spawn(move || {
                wait_for_rois(&fake, 1000);
                flag.store(true, Ordering::SeqCst);
            });
        },
        &mut |_| {},
    )
    .unwrap();
    assert!(
        matches!(
            report.loop_report.acquisition.stopped_by,
            Some(GrabError::Stopped { .. })
        ),
        "{:?}",
        report.loop_report.acquisition.stopped_by
    );
    assert!(!report.loop_report.estimates.is_empty());
    assert!(
        report.summary().contains("stopped: interrupted (Ctrl-C)"),
        "{}",
        report.summary()
    );
    // Clean: the camera and its port are released, another fake camera starts at once.
    let again = FakeGigeCamera::start(&scenario, Default::default(), 2).unwrap();
    assert!(again.is_running());
}

#[test]
fn a_camera_that_disappears_ends_the_run_with_a_clear_error_and_the_estimates_kept() {
    let _turn = turn();
    let scenario = Scenario::new(ScenarioKind::Orthoglide, 1);
    let options = LiveOptions {
        duration_s: 60.0,
        ..LiveOptions::default()
    };
    let report = run_fake(
        &scenario,
        &options,
        1,
        Arc::new(AtomicBool::new(false)),
        |fake| {
            std::thread::spawn(move || {
                wait_for_rois(&fake, 1000);
                fake.stop();
            });
        },
        &mut |_| {},
    )
    .unwrap();
    let stopped = report.loop_report.acquisition.stopped_by.clone();
    let Some(GrabError::Disconnected { reason }) = stopped else {
        panic!("expected a disconnection, got {stopped:?}");
    };
    assert!(reason.contains("127.0.0.1"), "{reason}");
    assert!(
        report.loop_report.estimates.len() > 50,
        "{}",
        report.summary()
    );
    assert!(
        report.summary().contains("the camera is disconnected"),
        "{}",
        report.summary()
    );
}
