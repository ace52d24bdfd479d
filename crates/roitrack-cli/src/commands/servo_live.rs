//! `roitrack servo --live`: the closed loop in real time (docs/servo.md, "The real-time loop"), through Aravis' fake
//! GigE camera (`--fake`, feature `genicam`) or the project's simulated ROI camera (`--sim-camera`), beside the
//! simulated-time run of the same configuration; this file only builds the camera, calls the library and prints.
//! With `--ros2`, the live loop's estimates go on the DDS bus as the loop makes them, as `live --ros2` publishes its
//! own: the estimation thread hands each one to the publisher (`roitrack_ros::ros2::Ros2Publisher`) through the
//! library's sink (`run_live_servo_with_sink`).

use anyhow::{Context, Result, bail};
use roitrack::Estimate;
use roitrack::servo::live::{
    LiveOptions, LiveServoReport, roi_camera_model, run_live_servo_simulated_with_sink,
};
use roitrack::servo::{CameraKind, CameraTiming, ControllerKind, ServoConfig, run_servo};

use super::servo::ServoArgs;

/// The camera a real-time run renders the robot through.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum LiveCamera {
    /// Aravis' fake GigE camera on 127.0.0.1 (feature `genicam`).
    AravisFake,
    /// The project's simulated ROI camera, on the acquisition thread.
    Simulated,
}

impl LiveCamera {
    fn name(self) -> &'static str {
        match self {
            Self::AravisFake => "live-aravis-fake",
            Self::Simulated => "live-sim-camera",
        }
    }
}

/// The configuration of both runs: the chosen controller (ctc by default) through the ROI camera at `--rate-hz`
/// ROIs and control ticks per second, the tracker told the commanded acceleration unless `--no-known-acceleration`
/// (in real time through the live loop's queue of known accelerations to its estimation thread).
fn config(args: &ServoArgs) -> Result<ServoConfig> {
    let controller: ControllerKind = args.controller.map_or(ControllerKind::Ctc, Into::into);
    if controller == ControllerKind::TrueState {
        bail!("--live runs a camera-fed controller: ctc, ctc-pose or kvs, not true-state");
    }
    if args.camera != super::servo::CameraArg::Roi {
        bail!("--live runs the ROI camera: --camera roi");
    }
    if args.sweep_gains {
        bail!("--live runs one closed loop: --sweep-gains is for the simulated-time runs");
    }
    let mut config = ServoConfig::new(controller, CameraKind::Roi, args.speed_scale);
    config.extra_latency_s = args.extra_latency_s;
    config.gains_follow_latency = !args.fixed_gains;
    config.gain_scale = args.gain_scale;
    config.extra_centroid_noise_px = 0.0;
    config.known_acceleration = !args.no_known_acceleration;
    config.seed = args.seed;
    config.control_rate_hz = args.rate_hz;
    config.timing = Some(CameraTiming {
        rate_hz: args.rate_hz,
        ..CameraKind::Roi.timing()
    });
    if args.extra_latency_s > 0.0 || args.centroid_noise_px > 0.0 {
        bail!(
            "--live measures its own latency and noise: no --extra-latency-s or --centroid-noise-px"
        );
    }
    Ok(config)
}

pub fn run(args: &ServoArgs) -> Result<()> {
    if args.pace.paced.is_some() {
        bail!(
            "--paced paces the publishing of a simulated-time run (servo without --live) to its own clock; --live \
             --ros2 publishes each estimate as the real-time loop makes it, already at the wall clock's pace"
        );
    }
    let camera = match (args.fake, args.sim_camera) {
        (true, false) => LiveCamera::AravisFake,
        (false, true) => LiveCamera::Simulated,
        _ => bail!(
            "--live needs its camera: --fake (Aravis' fake GigE camera, feature genicam) or --sim-camera (the \
             project's simulated ROI camera)"
        ),
    };
    if camera == LiveCamera::AravisFake && !cfg!(feature = "genicam") {
        // Said before the simulated-time run, not after.
        run_aravis_unavailable()?;
    }
    let config = config(args)?;
    if args.control_rate_hz.is_some_and(|hz| hz < args.rate_hz) {
        bail!("--control-rate-hz must be at least --rate-hz (one ROI slot a control tick at most)");
    }
    let live_options = LiveOptions {
        control_rate_hz: args.control_rate_hz,
        ..LiveOptions::default()
    };
    roitrack::formats::create_output_dir(&args.out)?;
    // --ros2: started before either run, so that a node that cannot start is an error before anything is computed;
    // the camera info is the live loop's camera.
    let mut ros2 = args
        .ros2
        .start(Some(&roi_camera_model(&config)), &Default::default())?;
    let simulated = run_servo(&config).context("the simulated-time run")?;
    // On the estimation thread, each estimate as the live loop makes it (a hand-over that never waits); a publisher
    // that failed does not stop the run, and its error comes after the outputs are written.
    let mut ros2_failed = None;
    let mut on_estimate = |e: &Estimate| {
        if ros2_failed.is_none() {
            ros2_failed = ros2.estimate(e).err();
        }
    };
    let (live, camera_line) = match camera {
        LiveCamera::Simulated => (
            run_live_servo_simulated_with_sink(&config, &live_options, &mut on_estimate)?,
            None,
        ),
        LiveCamera::AravisFake => {
            let (report, line) = run_aravis(&config, &live_options, &mut on_estimate)?;
            (report, Some(line))
        }
    };
    let name = config.controller.name();
    let sim_dir = args.out.join(format!("{name}-roi-simulated-time"));
    let live_dir = args.out.join(format!("{name}-{}", camera.name()));
    roitrack::servo::output::write_run(&simulated, &sim_dir)?;
    roitrack::servo::output::write_run(&live.servo, &live_dir)?;
    let figures =
        roitrack::servo::output::render_figures(&[simulated.clone(), live.servo.clone()])?;
    crate::commands::plot::write_figure_files(&args.out, &figures)?;
    if let Some(e) = ros2_failed {
        return Err(crate::OutputsStand(format!(
            "the ROS 2 publisher failed (the outputs are written): {e}"
        ))
        .into());
    }
    ros2.finish()?;
    print(
        args,
        camera,
        &config,
        &simulated,
        &live,
        camera_line.as_deref(),
        &live_dir,
    );
    Ok(())
}

#[cfg(feature = "genicam")]
fn run_aravis(
    config: &ServoConfig,
    live: &LiveOptions,
    on_estimate: &mut (dyn FnMut(&Estimate) + Send),
) -> Result<(LiveServoReport, String)> {
    use roitrack::servo::live::{
        LoopClockCamera, RobotScene, run_live_servo_with_sink, servo_target,
    };
    use roitrack::sim::SensorModel;
    use roitrack_genicam::{FakeGigeCamera, GenicamCamera, GenicamOptions};
    let scene = &RobotScene::new(&config.path);
    let model = roi_camera_model(config);
    let truth = {
        let scene = scene.clone();
        move |t: f64| scene.camera_state_at_loop_s(t)
    };
    let fake = FakeGigeCamera::start_rendering(
        &model,
        &servo_target(),
        truth,
        SensorModel::default(),
        config.seed,
    )?;
    let options = GenicamOptions {
        address: fake.address().to_string(),
        expected_serial: Some(fake.serial().to_string()),
        ..GenicamOptions::default()
    };
    let genicam = GenicamCamera::open(&options, (model.width_px, model.height_px))?
        .with_scene_clock(fake.clock());
    let (w, h) = genicam.window();
    let mut camera = LoopClockCamera::new(genicam, scene.clone());
    let live_options = LiveOptions {
        window_px: Some(w.min(h)),
        // The fake camera renders its 1024 x 1024 frame and sends it in packets: up to a second or more on two
        // shared cores; and a lost frame is retried after this long.
        full_frame_s: 1.0,
        start_timeout_s: 10.0,
        ..*live
    };
    let report = run_live_servo_with_sink(&mut camera, scene, config, &live_options, on_estimate);
    let stats = camera.inner().stats();
    let description = camera.inner().description().to_string();
    drop(camera);
    fake.stop();
    let grab = roitrack::core::stats::sorted(&stats.grab_us);
    let line = format!(
        "{description}: {} ROIs grabbed, {} lost, {} incomplete, {} stale; grab (move, trigger, buffer) p50/p99 \
         {:.0}/{:.0} us",
        stats.rois,
        stats.lost,
        stats.incomplete,
        stats.stale,
        roitrack::core::stats::quantile(&grab, 0.5),
        roitrack::core::stats::quantile(&grab, 0.99),
    );
    Ok((report?, line))
}

#[cfg(not(feature = "genicam"))]
fn run_aravis(
    _config: &ServoConfig,
    _options: &LiveOptions,
    _on_estimate: &mut (dyn FnMut(&Estimate) + Send),
) -> Result<(LiveServoReport, String)> {
    run_aravis_unavailable().map(|()| unreachable!("refused above"))
}

/// Refuses `--live --fake` in a build without the feature `genicam`, saying how to get it.
fn run_aravis_unavailable() -> Result<()> {
    if cfg!(feature = "genicam") {
        return Ok(());
    }
    bail!(
        "--live --fake runs Aravis' fake GigE camera: build with `--features genicam` (Debian's libaravis-dev), or \
         use --sim-camera (the project's simulated ROI camera)"
    )
}

fn print(
    args: &ServoArgs,
    camera: LiveCamera,
    config: &ServoConfig,
    simulated: &roitrack::servo::ServoReport,
    live: &LiveServoReport,
    camera_line: Option<&str>,
    live_dir: &std::path::Path,
) {
    let (act_p50, act_p99) = live.actuation_latency_quantiles_us();
    let (cmd_p50, cmd_p99) = live.command_latency_quantiles_us();
    let (est_p50, est_p99) = live.estimate_latency_quantiles_us();
    let ratio = live.servo.rms_error_mm / simulated.rms_error_mm;
    let loop_report = &live.loop_report;
    if args.json {
        let finite = |x: f64| x.is_finite().then_some(x);
        let line = serde_json::json!({
            "controller": config.controller.name(),
            "camera": camera.name(),
            "rate_hz": config.control_rate_hz,
            "control_rate_hz": args.control_rate_hz.unwrap_or(config.control_rate_hz),
            "speed_scale": args.speed_scale,
            "rms_error_mm": finite(live.servo.rms_error_mm),
            "max_error_mm": live.servo.max_error_mm,
            "stable": live.servo.stable,
            "stop_reason": live.servo.stop_reason,
            "simulated_time_rms_error_mm": simulated.rms_error_mm,
            "simulated_time_stable": simulated.stable,
            "rms_ratio_to_simulated_time": finite(ratio),
            "exposure_to_actuation_us_p50": finite(act_p50),
            "exposure_to_actuation_us_p99": finite(act_p99),
            "exposure_to_command_us_p50": finite(cmd_p50),
            "exposure_to_command_us_p99": finite(cmd_p99),
            "exposure_to_estimate_us_p50": finite(est_p50),
            "exposure_to_estimate_us_p99": finite(est_p99),
            "actuation_delay_us": config.actuation_delay_s * 1e6,
            "control_ticks": live.ticks,
            "missed_ticks": live.missed_ticks,
            "missed_ticks_before_start": live.missed_before_start,
            "longest_missed_run_ticks": live.longest_missed_run,
            "late_roi_slots": loop_report.acquisition.late,
            "skipped_roi_slots": loop_report.acquisition.skipped,
            "rois": loop_report.acquisition.rois,
            "initialisations": loop_report.acquisition.initialisations,
            "rois_per_s": loop_report.rois_per_s(),
            "estimates_published": live.published,
            "estimates_loop_to_path_s": live.loop_to_path_s,
            "known_acceleration": config.known_acceleration,
            "known_accelerations_sent": live.sent_known_accelerations,
            "known_accelerations_told": loop_report.known_accelerations,
            "known_accelerations_refused": loop_report.refused_known_accelerations,
            "known_accelerations_superseded": live.superseded_known_accelerations,
            "start_delay_s": finite(live.start_delay_s),
            "realtime_priority": live.realtime_priority,
            "natural_frequency_radps": live.servo.gains.natural_frequency_radps,
            "dir": live_dir.display().to_string(),
        });
        println!("{line}");
        return;
    }
    println!(
        "closed loop in real time: {} through {} at {:.0} ROIs/s and {:.0} control ticks/s, {} path at {} x 1 m/s",
        config.controller.name(),
        match camera {
            LiveCamera::AravisFake => "Aravis' fake GigE camera (127.0.0.1)",
            LiveCamera::Simulated =>
                "the project's simulated ROI camera (real clock, real threads)",
        },
        config.control_rate_hz,
        args.control_rate_hz.unwrap_or(config.control_rate_hz),
        config.path.name(),
        args.speed_scale
    );
    println!(
        "tracking error: real time {:.4} mm RMS ({:.4} max, stable {}); simulated time {:.4} mm RMS ({:.4} max, \
         stable {}); ratio {:.2}",
        live.servo.rms_error_mm,
        live.servo.max_error_mm,
        live.servo.stable,
        simulated.rms_error_mm,
        simulated.max_error_mm,
        simulated.stable,
        ratio
    );
    if let Some(reason) = &live.servo.stop_reason {
        println!("    stopped: {reason}");
    }
    println!(
        "latency p50/p99 from the ROI's mid-exposure: to the estimate {est_p50:.0}/{est_p99:.0} us, to the command \
         {cmd_p50:.0}/{cmd_p99:.0} us, to the actuation (the drive's {:.0} us delay added) {act_p50:.0}/{act_p99:.0} us",
        config.actuation_delay_s * 1e6
    );
    println!(
        "control thread: {} ticks, {} deadlines missed ({} before the path's start), real-time priority {}; live \
         loop: {} ROIs ({:.0} ROIs/s), {} slots reached more than a period late, {} skipped, {} estimates published; \
         path started {:.2} s after the loop",
        live.ticks,
        live.missed_ticks,
        live.missed_before_start,
        if live.realtime_priority {
            "SCHED_FIFO"
        } else {
            "refused (ordinary thread)"
        },
        loop_report.acquisition.rois,
        loop_report.rois_per_s(),
        loop_report.acquisition.late,
        loop_report.acquisition.skipped,
        live.published,
        live.start_delay_s
    );
    if config.known_acceleration {
        println!(
            "known acceleration: {} commands' accelerations sent to the live tracker, {} told, {} refused, {} \
             superseded (queue full)",
            live.sent_known_accelerations,
            loop_report.known_accelerations,
            loop_report.refused_known_accelerations,
            live.superseded_known_accelerations
        );
    } else {
        println!("known acceleration: off (--no-known-acceleration)");
    }
    if let Some(line) = camera_line {
        println!("{line}");
    }
    if args.ros2.ros2 {
        println!(
            "ROS 2: the estimates are stamped on the live loop's clock (the camera's); a stamp plus {:.9} s is the \
             estimate's time in the files (the path's clock)",
            live.loop_to_path_s
        );
    }
    println!("runs written to {}", args.out.display());
}
