//! The live loop through Aravis' fake GigE Vision camera on 127.0.0.1 (feature `genicam`): tracking as well as the
//! demo's simulated camera, the window moved as asked, a clean stop, a camera that disappears. Only one fake camera
//! can own 127.0.0.1: the tests take turns (a lock here; CI also runs them on one test thread).
#![cfg(feature = "genicam")]

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use roitrack_core::estimator::Estimate;
use roitrack_experiments::demo::{Demo, DemoOptions, lineup};
use roitrack_genicam::{FakeGigeCamera, LiveOptions, run_fake};
use roitrack_image::GrabError;
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

#[test]
fn tracks_through_the_protocol_within_twice_the_demo_error_and_moves_the_window() {
    let _turn = turn();
    let demo = Demo::new(DemoOptions::default()).unwrap();
    let kalman = &lineup()[0];
    let reference = demo.from_images(kalman, None).unwrap();
    let scenario = &demo.scenario;
    let duration_s = 2.0;
    let options = LiveOptions {
        duration_s,
        rate_hz: demo.simulation.rate_hz,
        tracker: demo.config(kalman),
        ..LiveOptions::default()
    };
    let report = run_fake(
        scenario,
        &options,
        1,
        Arc::new(AtomicBool::new(false)),
        |_| {},
    )
    .unwrap();
    println!("{}", report.summary());
    let reference_estimates = &reference.loop_report.as_ref().unwrap().estimates;
    let (demo_mm, demo_n) = position_rmse_mm(reference_estimates, scenario, duration_s);
    let (fake_mm, fake_n) = position_rmse_mm(&report.loop_report.estimates, scenario, duration_s);
    println!(
        "position RMSE up to {duration_s} s: fake camera {fake_mm:.4} mm ({fake_n} estimates), demo {demo_mm:.4} mm ({demo_n})"
    );
    assert!(
        report.loop_report.stopped_by.is_none(),
        "{:?}",
        report.loop_report.stopped_by
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
    let report = run_fake(&scenario, &options, 1, stop, move |fake| {
        std::thread::spawn(move || {
            wait_for_rois(&fake, 1000);
            flag.store(true, Ordering::SeqCst);
        });
    })
    .unwrap();
    assert!(
        matches!(
            report.loop_report.stopped_by,
            Some(GrabError::Stopped { .. })
        ),
        "{:?}",
        report.loop_report.stopped_by
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
    )
    .unwrap();
    let stopped = report.loop_report.stopped_by.clone();
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
