//! `roitrack servo`: close the loop on a simulated fast robot with roitrack's estimates (see docs/servo.md and the
//! library call `roitrack::servo::run_servo`); this file only translates the options and prints.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Args, ValueEnum};
use roitrack::servo::{CameraKind, ControllerKind, ServoConfig, run_servo};

use crate::ranges;

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ControllerArg {
    /// Computed torque with the tracker's pose and velocity, each predicted to the actuation instant.
    Ctc,
    /// The same with pose only (velocity by differences of the estimated positions).
    CtcPose,
    /// Kinematic visual servo: velocity commands into the drives' joint-velocity loop.
    Kvs,
    /// Computed torque on the true state with no delay: the floor.
    TrueState,
}

impl From<ControllerArg> for ControllerKind {
    fn from(c: ControllerArg) -> Self {
        match c {
            ControllerArg::Ctc => Self::Ctc,
            ControllerArg::CtcPose => Self::CtcPose,
            ControllerArg::Kvs => Self::Kvs,
            ControllerArg::TrueState => Self::TrueState,
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CameraArg {
    /// The ROI camera at 4 kHz, an estimate every 10 ROIs.
    Roi,
    /// A 120 Hz global-shutter frame camera through the frame tracker.
    #[value(name = "frames-120")]
    Frames120,
    /// A 30 Hz global-shutter frame camera through the frame tracker.
    #[value(name = "frames-30")]
    Frames30,
}

impl From<CameraArg> for CameraKind {
    fn from(c: CameraArg) -> Self {
        match c {
            CameraArg::Roi => Self::Roi,
            CameraArg::Frames120 => Self::Frames120,
            CameraArg::Frames30 => Self::Frames30,
        }
    }
}

/// Servo a simulated Orthoglide-like robot along the orthoglide path (1 m/s peak times --speed-scale) with the
/// controllers fed by the simulated camera and roitrack's tracker, the controller's model 20 % off the robot's
/// masses; print a table of tracking errors and write, per run, a folder <out>/<controller>-<camera> with
/// reference.tum, achieved.tum (commanded and true platform poses), the tracker's estimates and servo.csv (per tick:
/// path, platform, error, actuator forces). A run that diverges is stopped and reported unstable.
#[derive(Debug, Args)]
pub struct ServoArgs {
    /// One controller; default: ctc, ctc-pose and kvs through the camera, and the true-state floor.
    #[arg(long, value_enum)]
    pub controller: Option<ControllerArg>,
    /// The camera the controllers see the robot through (true-state sees the truth whatever this says).
    #[arg(long, value_enum, default_value = "roi")]
    pub camera: CameraArg,
    /// The path played this many times faster (2: 2 m/s peak), from 0.1 to 4.
    #[arg(long, default_value_t = 1.0, value_parser = ranges::within(0.1..=4.0, "", "a path played at up to 4 m/s"))]
    pub speed_scale: f64,
    /// Latency added between the camera and the controller (s), at most 0.1; the gains follow the whole latency
    /// unless --fixed-gains.
    #[arg(long, default_value_t = 0.0, value_parser = ranges::within(0.0..=0.1, " s", "a tenth of a second"))]
    pub extra_latency_s: f64,
    /// Keep the gains tuned for the camera's own latency, whatever --extra-latency-s adds (to see what an
    /// unforeseen delay does).
    #[arg(long)]
    pub fixed_gains: bool,
    /// The gains' natural frequency (rad/s; λ for kvs) times this, from 0.01 to 100 (to find the stability limit by
    /// hand).
    #[arg(long, default_value_t = 1.0, value_parser = ranges::within(0.01..=100.0, "", "a hundred times the rule's gain"))]
    pub gain_scale: f64,
    /// Also find, for each controller, the largest stable gain against extra latency (0 to 4 ms) and write
    /// stable_gain.csv and servo_stable_gain.png/svg (a few hundred runs: minutes).
    #[arg(long)]
    pub sweep_gains: bool,
    /// Gaussian noise added to each ROI centroid (px, per axis), from 0 to 2, on top of the rendered images' own
    /// (about 0.013 px); 0.1: the built-in scenes' noise.
    #[arg(long, default_value_t = 0.0, value_parser = ranges::within(0.0..=2.0, " px", "2 px"))]
    pub centroid_noise_px: f64,
    /// Do not tell the tracker the acceleration the controller commands (its model's, from the instant the force
    /// acts): the Kalman filter then predicts with its constant-velocity model alone, as before (to compare).
    #[arg(long)]
    pub no_known_acceleration: bool,
    /// Seed of the camera's noise.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// One JSON object per run on a line (controller, camera, rms_error_mm, max_error_mm, stable, dir, ...)
    /// instead of the table.
    #[arg(long)]
    pub json: bool,
    /// Run the closed loop in real time: the controller on its own thread on the wall clock, fed by the live
    /// two-thread loop through the estimate handle, the camera rendering the simulated robot where it is now; beside
    /// the simulated-time run of the same configuration. Needs --fake or --sim-camera; prints the tracking errors,
    /// the latency from exposure to actuation (median, p99) and the deadlines missed.
    #[arg(long)]
    pub live: bool,
    /// With --live: the camera is Aravis' fake GigE camera on 127.0.0.1 (feature genicam).
    #[arg(long, requires = "live")]
    pub fake: bool,
    /// With --live: the camera is the project's simulated ROI camera, on the live loop's acquisition thread.
    #[arg(long, requires = "live", conflicts_with = "fake")]
    pub sim_camera: bool,
    /// With --live: ROIs and control ticks per second, from 500 to 4000 (a rate the machine cannot hold is run and
    /// its missed deadlines and late ROI slots reported).
    #[arg(long, default_value_t = 2000.0, requires = "live", value_parser = ranges::within(500.0..=4000.0, " Hz", "4 kHz"))]
    pub rate_hz: f64,
    /// With --live: the control thread's rate (Hz), from --rate-hz to 4000, when it should tick faster than the
    /// ROIs (a command then follows each estimate sooner); default: --rate-hz.
    #[arg(long, requires = "live", value_parser = ranges::within(500.0..=4000.0, " Hz", "4 kHz"))]
    pub control_rate_hz: Option<f64>,
    /// Output folder (created if missing); one folder per run inside.
    #[arg(long)]
    pub out: PathBuf,
    /// --ros2: the run's estimates on the ROS 2 DDS bus, as `track --ros2` publishes them (one run: give
    /// --controller); with --live, the real-time loop's as it makes them, as `live --ros2` does.
    #[command(flatten)]
    pub ros2: crate::ros2_args::Ros2Args,
    /// --paced: the estimates published at the run's own speed (simulated time runs faster than the wall clock); not
    /// with --live, which runs on the wall clock.
    #[command(flatten)]
    pub pace: crate::ros::PaceArgs,
}

pub fn run(args: &ServoArgs) -> Result<()> {
    if args.live {
        return super::servo_live::run(args);
    }
    let controllers: Vec<ControllerKind> = match args.controller {
        Some(c) => vec![c.into()],
        None => ControllerKind::ALL.to_vec(),
    };
    if args.pace.paced.is_some() && !args.ros2.ros2 {
        anyhow::bail!("--paced paces what --ros2 publishes, and --ros2 is not given");
    }
    if args.ros2.ros2 && !matches!(controllers.as_slice(), [c] if *c != ControllerKind::TrueState) {
        anyhow::bail!(
            "--ros2 publishes one run's estimates: give --controller ctc, ctc-pose or kvs (true-state estimates \
             nothing)"
        );
    }
    roitrack::formats::create_output_dir(&args.out)?;
    // Started before the run (--ros2 has one controller, which a camera sees): a node that cannot start is an error
    // before anything is computed or printed.
    let mut ros2 = match ServoConfig::new(controllers[0], args.camera.into(), args.speed_scale)
        .camera_model()
    {
        Some(camera) if args.ros2.ros2 => {
            Some(args.ros2.start(Some(&camera), &Default::default())?)
        }
        _ => None,
    };
    let mut reports = Vec::new();
    if !args.json {
        println!(
            "{:<11} {:<10} {:>8} {:>8} {:>6} {:>9} {:>8}  dir",
            "controller", "camera", "rms_mm", "max_mm", "stable", "omega_rad", "age_ms"
        );
    }
    for &controller in &controllers {
        let mut config = ServoConfig::new(controller, args.camera.into(), args.speed_scale);
        config.extra_latency_s = args.extra_latency_s;
        config.gains_follow_latency = !args.fixed_gains;
        config.gain_scale = args.gain_scale;
        config.extra_centroid_noise_px = args.centroid_noise_px;
        config.known_acceleration = !args.no_known_acceleration;
        config.seed = args.seed;
        let report =
            run_servo(&config).with_context(|| format!("servo run {}", controller.name()))?;
        if let Some(mut ros2) = ros2.take() {
            let mut pacer = args.pace.pacer();
            for e in &report.estimates {
                if let Some(pacer) = &mut pacer {
                    pacer.wait_until(e.t_ref_s);
                }
                ros2.estimate(e)?;
            }
            ros2.finish()?;
        }
        let dir = args.out.join(format!(
            "{}-{}",
            report.controller.name(),
            report.camera.name()
        ));
        roitrack::servo::output::write_run(&report, &dir)?;
        let age_ms = report.median_feedback_age_s * 1e3;
        if args.json {
            let line = serde_json::json!({
                "controller": report.controller.name(),
                "camera": report.camera.name(),
                "speed_scale": args.speed_scale,
                "extra_latency_s": args.extra_latency_s,
                "rms_error_mm": report.rms_error_mm,
                "max_error_mm": report.max_error_mm,
                "stable": report.stable,
                "stop_reason": report.stop_reason,
                "natural_frequency_radps": report.gains.natural_frequency_radps,
                "median_feedback_age_ms": age_ms.is_finite().then_some(age_ms),
                "saturated_fraction": report.saturated_fraction,
                "known_acceleration": !args.no_known_acceleration,
                "dir": dir.display().to_string(),
            });
            println!("{line}");
        } else {
            println!(
                "{:<11} {:<10} {:>8.4} {:>8.4} {:>6} {:>9.0} {:>8.3}  {}",
                report.controller.name(),
                report.camera.name(),
                report.rms_error_mm,
                report.max_error_mm,
                report.stable,
                report.gains.natural_frequency_radps,
                age_ms,
                dir.display()
            );
            if let Some(reason) = &report.stop_reason {
                println!("    stopped: {reason}");
            }
        }
        reports.push(report);
    }
    let figures = roitrack::servo::output::render_figures(&reports)?;
    crate::commands::plot::write_figure_files(&args.out, &figures)?;
    if args.sweep_gains {
        sweep(args, &controllers)?;
    }
    Ok(())
}

/// The largest stable gain against extra latency of each controller: a table, `stable_gain.csv` and the figure.
fn sweep(args: &ServoArgs, controllers: &[ControllerKind]) -> Result<()> {
    use roitrack::servo::sweep;
    let search = sweep::GainSearch::default();
    let mut curves = Vec::new();
    let mut rows = Vec::new();
    if !args.json {
        println!("\n{}", sweep::TABLE_HEADER);
    }
    for &controller in controllers {
        let mut config = ServoConfig::new(controller, args.camera.into(), args.speed_scale);
        config.seed = args.seed;
        config.extra_centroid_noise_px = args.centroid_noise_px;
        config.known_acceleration = !args.no_known_acceleration;
        let points = sweep::stable_gain_sweep(&config, &sweep::EXTRA_LATENCIES_S, &search)
            .with_context(|| format!("gain sweep of {}", controller.name()))?;
        for point in &points {
            let row = sweep::Row {
                controller,
                camera: config.camera,
                point: *point,
            };
            if args.json {
                println!(
                    "{}",
                    serde_json::json!({
                        "sweep": "stable_gain",
                        "controller": controller.name(),
                        "camera": config.camera.name(),
                        "extra_latency_s": point.extra_latency_s,
                        "largest_stable_radps": point.largest_stable_radps,
                        "rule_radps": point.rule_radps,
                    })
                );
            } else {
                println!("{}", row.table_row());
            }
            rows.push(row);
        }
        curves.push(sweep::curve(controller, config.camera, &points));
    }
    let mut csv = roitrack::formats::AtomicFile::create(args.out.join(sweep::CSV_FILE))?;
    use std::io::Write as _;
    writeln!(csv, "{}", sweep::CSV_HEADER)?;
    for row in &rows {
        writeln!(csv, "{}", row.csv_row())?;
    }
    csv.finish()?;
    crate::commands::plot::write_figure_files(
        &args.out,
        &roitrack::plot::servo::render_stable_gain(&curves)?,
    )?;
    Ok(())
}
