//! `roitrack live` and `roitrack cameras` (feature `genicam`): the two-thread loop on a live GenICam camera through
//! Aravis, or on Aravis' fake GigE camera rendering a scenario (see `roitrack_genicam`, docs/cameras.md).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use clap::{Args, ValueEnum};
use roitrack::estimators::rig::RigEstimate;
use roitrack::formats::EstimateWriter;
use roitrack::sim::Scenario;
use roitrack::sim::multi_camera::{CameraRigScene, draw_clocks};
use roitrack_genicam::{
    GenicamOptions, LiveOptions, PixelFormatChoice, TriggerChoice, run_device, run_device_rig,
    run_fake, run_fake_rig, truth_samples,
};

use crate::args::ScenarioArg;

/// Track from a live GenICam camera (GigE Vision, USB3 Vision) through Aravis, or from Aravis' fake GigE camera
/// rendering a simulated target (--fake): a first full frame, then one ROI at a time where the tracker predicts each
/// blob. Ctrl-C stops the run and writes every output.
#[derive(Debug, Args)]
pub struct LiveArgs {
    /// The camera's IPv4 address (GigE Vision), opened directly; an Aravis id (Vendor-Model-Serial, USB3 Vision)
    /// only with --allow-discovery. With --rig: NAME=ADDRESS, once for each camera of the rig. Default: none; one of
    /// --device and --fake is required.
    #[arg(
        long,
        value_name = "ADDRESS",
        required_unless_present = "fake",
        conflicts_with = "fake"
    )]
    pub device: Vec<String>,
    /// With --device: let Aravis search for a camera given by its id: a GigE Vision discovery broadcast on every
    /// network interface, then the USB bus (USB3 Vision cameras need it). Without it, only an IP address is opened.
    #[arg(long, requires = "device")]
    pub allow_discovery: bool,
    /// Start Aravis' fake GigE camera on 127.0.0.1 in this process and track the scenario it renders. With --rig:
    /// one fake camera per camera of the rig, camera k on 127.0.0.k (every address but 127.0.0.1 must be on the
    /// loopback first: `ip addr add 127.0.0.2/8 dev lo`), each rendering the scenario through its calibration, pose
    /// and clock (the clocks the rig file leaves out drawn from --seed, within ±50 ms and ±100 ppm).
    #[arg(long)]
    pub fake: bool,
    /// Several cameras that share no clock, one fused track: the rig file (docs/rig.md) with each camera's
    /// calibration and pose; each camera runs on a thread of its own, its ROIs placed from its own track, and every
    /// centroid is fused in the order of the rig's time; clocks the file leaves out are learnt. The poses and twists
    /// are rig_T_object in the rig's frame on the rig's clock. Give each camera's address (--device NAME=ADDRESS) or
    /// --fake. Default: one camera.
    #[arg(long, value_name = "RIG.yaml", conflicts_with_all = ["camera", "allow_discovery"])]
    pub rig: Option<PathBuf>,
    /// With --rig: also write the rig file with the clocks learnt (offsets, drifts and their standard deviations).
    /// Default: none.
    #[arg(long, value_name = "FILE.yaml", requires = "rig")]
    pub rig_out: Option<PathBuf>,
    /// With --fake: the scenario rendered.
    #[arg(long, value_enum, default_value = "orthoglide", requires = "fake")]
    pub scenario: ScenarioArg,
    /// With --fake: seed of the scenario and of the pixel noise.
    #[arg(long, default_value_t = 1, requires = "fake")]
    pub seed: u64,
    /// With --fake: also write the ground truth (gt_poses.tum, gt_twists.csv) on the fake camera's clock, the
    /// scenario's time, into this folder (with --rig: in the rig's frame on the rig's clock, and rig_truth.yaml, the
    /// rig with the clocks drawn). Default: none.
    #[arg(long, value_name = "DIR", requires = "fake")]
    pub truth_out: Option<PathBuf>,
    /// With --device: the camera's calibration (any format `track --camera` reads). Default: none (required with
    /// --device, but with --rig, whose file gives each camera's).
    #[arg(
        long,
        value_name = "FILE",
        required_unless_present_any = ["fake", "rig"],
        conflicts_with = "fake"
    )]
    pub camera: Option<PathBuf>,
    /// With --device: the target (CSV id,x,y,z[,diameter], metres). Default: none (required with --device).
    #[arg(
        long,
        value_name = "FILE.csv",
        required_unless_present = "fake",
        conflicts_with = "fake"
    )]
    pub target: Option<PathBuf>,
    /// Length of the run (s). Default: the scenario's with --fake (a longer one stops at its end), 10 s with
    /// --device.
    #[arg(long, value_name = "S", value_parser = crate::ranges::positive_up_to(86_400.0, " s", "a day"))]
    pub duration: Option<f64>,
    /// Side of the square window every ROI is read through (px, at most 64), rounded up to the camera's increments.
    #[arg(long, value_name = "N", default_value_t = 32)]
    pub roi_size: u32,
    /// ROI slots per second: with --device the loop is paced at this rate on the host's clock (the camera must
    /// sustain it); with --fake the slots are the scenario's times, read as fast as the camera delivers. Default:
    /// 4000 with --fake, 1000 with --device.
    #[arg(long, value_name = "HZ", value_parser = crate::ranges::positive_up_to(roitrack::sim::MAX_ROI_RATE_HZ, " Hz", "beyond any ROI camera"))]
    pub rate_hz: Option<f64>,
    /// ExposureTime (µs). Default: the camera's.
    #[arg(long, value_name = "US", value_parser = crate::ranges::positive_up_to(roitrack::core::time::MAX_EXPOSURE_S * 1e6, " µs", "beyond, a moving blob is a streak"))]
    pub exposure_us: Option<f64>,
    /// Pixel format (one the camera does not offer is refused with the list of those it does). Default: mono8 if the
    /// camera offers it, else the first of mono12, mono16, mono12-packed, mono12p it offers. The fake camera offers
    /// mono8 and mono16.
    #[arg(long, value_enum)]
    pub pixel_format: Option<PixelFormatArg>,
    /// How each ROI is started: a software trigger once the window moved, or the camera's free run (frames still
    /// from the old window are skipped).
    #[arg(long, value_enum, default_value = "software")]
    pub trigger: TriggerArg,
    /// With --trigger free-run: AcquisitionFrameRate (Hz). Default: the camera's.
    #[arg(long, value_name = "HZ", value_parser = crate::ranges::within(roitrack::formats::MIN_FRAME_RATE_HZ..=roitrack::formats::MAX_FRAME_RATE_HZ, " Hz", "a frame every 1,000 s to beyond the fastest cameras"))]
    pub frame_rate_hz: Option<f64>,
    /// How long a ROI may take before it counts as lost (s).
    #[arg(long, value_name = "S", default_value_t = 0.2, value_parser = crate::ranges::positive_up_to(60.0, " s", "a minute"))]
    pub timeout_s: f64,
    /// Output: the poses (TUM). Required.
    #[arg(long, value_name = "P.tum")]
    pub poses: PathBuf,
    /// Output: the twists (CSV). Required.
    #[arg(long, value_name = "T.csv")]
    pub twists: PathBuf,
    #[command(flatten)]
    pub ros: crate::ros::McapArgs,
    #[command(flatten)]
    pub ros2: crate::ros2_args::Ros2Args,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum PixelFormatArg {
    Mono8,
    Mono12,
    Mono16,
    /// GigE Vision's Mono12Packed (two pixels in three bytes).
    Mono12Packed,
    /// PFNC's Mono12p (two pixels in three bytes, least significant bits first).
    Mono12p,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum TriggerArg {
    Software,
    FreeRun,
}

/// List the GenICam cameras Aravis finds. Only with --scan: GigE Vision discovery broadcasts on every network
/// interface, which roitrack never does unasked (open a camera by its address with `live --device`).
#[derive(Debug, Args)]
pub struct CamerasArgs {
    /// Scan every interface (GigE Vision broadcast, USB3 Vision bus).
    #[arg(long)]
    pub scan: bool,
}

pub fn cameras(args: &CamerasArgs) -> Result<()> {
    if !args.scan {
        bail!(
            "roitrack does not scan the network unasked: give --scan to broadcast a GigE Vision discovery on every \
             interface and list the USB3 Vision cameras"
        );
    }
    let found = roitrack_genicam::scan();
    if found.is_empty() {
        println!("no camera found");
    }
    for (id, address, protocol) in found {
        println!("{id}\t{address}\t{protocol}");
    }
    Ok(())
}

/// Refuses, before anything is read or written, outputs (poses, twists, the bag and its partial name, the truth's
/// files) that are the camera or target file (also through links) or each other.
fn check_paths(args: &LiveArgs) -> Result<()> {
    let inputs: Vec<(&str, &std::path::Path)> = [
        ("--camera", &args.camera),
        ("--target", &args.target),
        ("--rig", &args.rig),
    ]
    .into_iter()
    .filter_map(|(name, path)| path.as_deref().map(|p| (name, p)))
    .collect();
    let mut outputs: Vec<(&str, PathBuf)> = vec![
        ("--poses", args.poses.clone()),
        ("--twists", args.twists.clone()),
    ];
    if let Some(out) = &args.rig_out {
        outputs.push(("--rig-out", out.clone()));
    }
    if let Some(mcap) = &args.ros.mcap {
        outputs.push(("--mcap", mcap.clone()));
        outputs.push((
            "--mcap's partial bag",
            roitrack::formats::partial_path(mcap),
        ));
    }
    if let Some(dir) = &args.truth_out {
        outputs.push((
            "--truth-out's gt_poses.tum",
            dir.join(super::simulate::TRUTH_POSES_FILE),
        ));
        outputs.push((
            "--truth-out's gt_twists.csv",
            dir.join(super::simulate::TRUTH_TWISTS_FILE),
        ));
        if args.rig.is_some() {
            outputs.push((
                "--truth-out's rig_truth.yaml",
                dir.join(super::simulate::RIG_TRUTH_FILE),
            ));
        }
    }
    let outputs: Vec<(&str, &std::path::Path)> =
        outputs.iter().map(|(n, p)| (*n, p.as_path())).collect();
    Ok(roitrack::formats::check_output_paths(&inputs, &outputs)?)
}

pub fn run(args: &LiveArgs) -> Result<()> {
    if args.roi_size == 0 || args.roi_size > 64 {
        bail!("--roi-size must be in 1..=64 px, got {}", args.roi_size);
    }
    let camera = camera_options(args);
    if let Some(rig) = &args.rig {
        return run_rig(args, rig, camera);
    }
    let camera = match args.device.as_slice() {
        [] => camera,
        [address] => GenicamOptions {
            address: address.clone(),
            ..camera
        },
        _ => bail!("--device: one camera, or several with --rig (NAME=ADDRESS each)"),
    };
    check_paths(args)?;
    // The truth's folder first: the estimates may go into it.
    if let Some(dir) = &args.truth_out {
        roitrack::formats::create_output_dir(dir)?;
    }
    // Started before the camera, so that a bad output path fails first; finished whatever the run's end.
    let mut writer = EstimateWriter::create(&args.poses, &args.twists, None)?;
    let scenario = Scenario::new(args.scenario.into(), args.seed);
    let (camera_model, target) = if args.fake {
        (scenario.camera.clone(), scenario.target.clone())
    } else {
        let camera_model = roitrack::formats::read_camera_file(
            args.camera
                .as_ref()
                .context("--camera is required with --device")?,
            &Default::default(),
        )?;
        let target = device_target(args)?;
        (camera_model, target)
    };
    // The first signal stops the run at its next ROI; the bag is completed below with every estimate.
    let mut bag = args.ros.open(Some(&camera_model), Some(&target))?;
    let mut outputs =
        LiveOutputs::start(args, &mut bag, Some(&camera_model), &args.ros.bag_options())?;
    let mut on_estimate = |e: &roitrack::Estimate| outputs.estimate(e);
    // The stop flag the camera reads: for a live run the usual way to end, which writes every output.
    let stop = crate::signals::stop_flag();
    let report = if args.fake {
        let options = LiveOptions {
            camera,
            duration_s: args.duration.unwrap_or(scenario.duration_s),
            rate_hz: args.rate_hz.unwrap_or(4000.0),
            keep_measurements: args.ros.mcap.is_some(),
            ..LiveOptions::default()
        };
        if let Some(dir) = &args.truth_out {
            let (poses, twists) = truth_samples(&scenario, options.duration_s, options.rate_hz);
            roitrack::formats::write_tum(dir.join(super::simulate::TRUTH_POSES_FILE), &poses)?;
            roitrack::formats::write_twists_csv(
                dir.join(super::simulate::TRUTH_TWISTS_FILE),
                &twists,
            )?;
        }
        run_fake(
            &scenario,
            &options,
            args.seed,
            stop,
            |_| {},
            &mut on_estimate,
        )?
    } else {
        let options = LiveOptions {
            camera,
            duration_s: args.duration.unwrap_or(10.0),
            rate_hz: args.rate_hz.unwrap_or(1000.0),
            keep_measurements: args.ros.mcap.is_some(),
            ..LiveOptions::default()
        };
        run_device(&camera_model, &target, &options, stop, &mut on_estimate)?
    };
    for e in &report.loop_report.estimates {
        writer.write(e)?;
    }
    bag.run(&report.loop_report.measured, &report.loop_report.estimates)?;
    writer.finish()?;
    bag.finish()?;
    outputs.finish()?;
    println!("{}", report.summary());
    println!(
        "wrote {} estimates to {} and {}",
        report.loop_report.estimates.len(),
        args.poses.display(),
        args.twists.display()
    );
    match &report.loop_report.acquisition.stopped_by {
        Some(roitrack::image::GrabError::Stopped { .. }) => {
            // Stopped by a signal: the run's normal end, its outputs committed.
            crate::signals::acknowledge();
            Ok(())
        }
        None => Ok(()),
        Some(e) => Err(crate::OutputsStand(format!(
            "the camera ended the run: {e} (the estimates until then are written)"
        ))
        .into()),
    }
}

/// The live view (--foxglove) and the DDS bus (--ros2), fed from the loop's estimation thread as it tracks (the bag
/// takes the estimates at the end), and the first failure of each, which stops feeding it.
struct LiveOutputs {
    live: Option<roitrack::ros::LiveServer>,
    live_failed: Option<roitrack::formats::FormatError>,
    ros2: crate::ros2_args::Ros2,
    ros2_failed: Option<roitrack::formats::FormatError>,
}

impl LiveOutputs {
    /// Takes the live view out of `bag` and starts --ros2 with `camera` (none for a rig) and `options`: a node that
    /// cannot start fails here, before any camera is opened.
    fn start(
        args: &LiveArgs,
        bag: &mut crate::ros::Bag,
        camera: Option<&roitrack::CameraModel>,
        options: &roitrack::ros::BagOptions,
    ) -> Result<Self> {
        Ok(Self {
            live: bag.take_live(),
            live_failed: None,
            ros2: args.ros2.start(camera, options)?,
            ros2_failed: None,
        })
    }

    /// An estimate, to each output that has not failed.
    fn estimate(&mut self, e: &roitrack::Estimate) {
        if let Some(live) = self.live.as_mut()
            && self.live_failed.is_none()
        {
            self.live_failed = live.publish_estimate(e).err();
        }
        if self.ros2_failed.is_none() {
            self.ros2_failed = self.ros2.estimate(e).err();
        }
    }

    /// Ends both, once the files are written: a live view or a ROS 2 publisher that failed does not cost them.
    fn finish(self) -> Result<()> {
        if let Some(e) = self.live_failed {
            return Err(crate::OutputsStand(format!(
                "the live view failed (the outputs are written): {e}"
            ))
            .into());
        }
        if let Some(e) = self.ros2_failed {
            return Err(crate::OutputsStand(format!(
                "the ROS 2 publisher failed (the outputs are written): {e}"
            ))
            .into());
        }
        if let Some(live) = self.live {
            crate::ros::finish_live(live)?;
        }
        self.ros2.finish()
    }
}

/// `live --rig`: the rig's cameras (fake, or each at its --device NAME=ADDRESS) in one loop, one fused track.
fn run_rig(args: &LiveArgs, rig_path: &Path, camera: GenicamOptions) -> Result<()> {
    if args.ros.mcap_rois {
        bail!("--mcap-rois: a rig's bag holds its fused estimates only");
    }
    check_paths(args)?;
    let file = roitrack::formats::read_rig_yaml(rig_path, &Default::default())?;
    let rig = &file.rig;
    let names: Vec<String> = rig.cameras().iter().map(|c| c.name.clone()).collect();
    if let Some(dir) = &args.truth_out {
        roitrack::formats::create_output_dir(dir)?;
    }
    let mut writer = EstimateWriter::create(&args.poses, &args.twists, None)?;
    // The fused estimates (rig frame, rig clock) to the bag at the end, and as they come to the live view and the
    // DDS bus.
    let bag_options = args.ros.rig_bag_options();
    let mut bag = args.ros.open_with_options(None, None, &bag_options)?;
    let mut outputs = LiveOutputs::start(args, &mut bag, None, &bag_options)?;
    let mut on_estimate = |e: &RigEstimate| outputs.estimate(&e.estimate);
    let stop = crate::signals::stop_flag();
    let report = if args.fake {
        run_fake_rig_writing_truth(args, &file, rig_path, camera, stop, &mut on_estimate)?
    } else {
        let target = device_target(args)?;
        let cameras = device_rig_cameras(args, rig_path, rig, &names, &camera)?;
        let options = LiveOptions {
            camera,
            duration_s: args.duration.unwrap_or(10.0),
            rate_hz: args.rate_hz.unwrap_or(1000.0),
            ..LiveOptions::default()
        };
        run_device_rig(rig, &cameras, &target, &options, stop, &mut on_estimate)?
    };
    let estimates: Vec<roitrack::Estimate> = report
        .loop_report
        .estimates
        .iter()
        .map(|e| e.estimate)
        .collect();
    for e in &estimates {
        writer.write(e)?;
    }
    bag.run(&[], &estimates)?;
    writer.finish()?;
    bag.finish()?;
    outputs.finish()?;
    if let Some(out) = &args.rig_out {
        let calibrations = file.calibrations_for_output(out);
        roitrack::formats::write_rig_yaml(
            out,
            rig,
            &calibrations,
            Some(&report.loop_report.clocks),
        )?;
    }
    println!("{}", report.summary(&names));
    println!(
        "wrote {} estimates to {} and {}",
        report.loop_report.estimates.len(),
        args.poses.display(),
        args.twists.display()
    );
    cameras_that_ended_the_run(&report, &names)
}

/// `live --rig --fake`: the rig's cameras simulated (their clocks drawn from the seed) on the scenario; with
/// --truth-out, the truth's poses and twists and the rig as simulated written there first.
fn run_fake_rig_writing_truth(
    args: &LiveArgs,
    file: &roitrack::formats::RigFile,
    rig_path: &Path,
    camera: GenicamOptions,
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    on_estimate: &mut (dyn FnMut(&RigEstimate) + Send),
) -> Result<roitrack_genicam::RigLiveReport> {
    let rig = &file.rig;
    let scenario = Scenario::new(args.scenario.into(), args.seed);
    let scene = CameraRigScene {
        rig: draw_clocks(rig, args.seed),
        scenario,
    };
    let options = LiveOptions {
        camera,
        duration_s: args.duration.unwrap_or(scene.scenario.duration_s),
        rate_hz: args.rate_hz.unwrap_or(4000.0),
        ..LiveOptions::default()
    };
    if let Some(dir) = &args.truth_out {
        let (poses, twists) = truth_samples(&scene.scenario, options.duration_s, options.rate_hz);
        roitrack::formats::write_tum(dir.join(super::simulate::TRUTH_POSES_FILE), &poses)?;
        roitrack::formats::write_twists_csv(dir.join(super::simulate::TRUTH_TWISTS_FILE), &twists)?;
        let truth_file = dir.join(super::simulate::RIG_TRUTH_FILE);
        let calibrations = file.calibrations_for_output(&truth_file);
        roitrack::formats::write_rig_yaml(&truth_file, &scene.rig, &calibrations, None)?;
    }
    let report = run_fake_rig(&scene, rig, &options, args.seed, stop, on_estimate)
        .with_context(|| format!("the fake cameras of {}", rig_path.display()))?;
    Ok(report)
}

/// Each camera of the rig with its address from --device NAME=ADDRESS (every camera given once) and the options
/// all cameras take.
fn device_rig_cameras(
    args: &LiveArgs,
    rig_path: &Path,
    rig: &roitrack::estimators::rig::Rig,
    names: &[String],
    camera: &GenicamOptions,
) -> Result<Vec<GenicamOptions>> {
    let mut addresses: Vec<Option<String>> = vec![None; rig.len()];
    for given in &args.device {
        let Some((name, address)) = given.split_once('=') else {
            bail!(
                "--device {given}: with --rig, NAME=ADDRESS (a camera of {})",
                rig_path.display()
            );
        };
        let Some(c) = rig.index_of(name) else {
            bail!(
                "--device {given}: {} has no camera '{name}' (it has {})",
                rig_path.display(),
                names.join(", ")
            );
        };
        if addresses[c].replace(address.to_string()).is_some() {
            bail!("--device: camera '{name}' given twice");
        }
    }
    addresses
        .into_iter()
        .zip(names)
        .map(|(address, name)| {
            let address = address.with_context(|| {
                format!(
                    "camera '{name}' of {} has no --device {name}=ADDRESS",
                    rig_path.display()
                )
            })?;
            Ok(GenicamOptions {
                address,
                ..camera.clone()
            })
        })
        .collect()
}

/// An error naming each camera that ended the run by an error of its own (the estimates until then are written);
/// a camera stopped by a signal is not one, and the signal is acknowledged.
fn cameras_that_ended_the_run(
    report: &roitrack_genicam::RigLiveReport,
    names: &[String],
) -> Result<()> {
    let stopped: Vec<String> = report
        .loop_report
        .cameras
        .iter()
        .zip(names)
        .filter_map(|(counts, name)| match &counts.stopped_by {
            None | Some(roitrack::image::GrabError::Stopped { .. }) => None,
            Some(e) => Some(format!("camera '{name}': {e}")),
        })
        .collect();
    if report.loop_report.cameras.iter().any(|c| {
        matches!(
            c.stopped_by,
            Some(roitrack::image::GrabError::Stopped { .. })
        )
    }) {
        crate::signals::acknowledge();
    }
    if !stopped.is_empty() {
        return Err(crate::OutputsStand(format!(
            "a camera ended the run: {} (the estimates until then are written)",
            stopped.join("; ")
        ))
        .into());
    }
    Ok(())
}

/// The target of a run on real cameras (--target, required with --device).
fn device_target(args: &LiveArgs) -> Result<roitrack::Target> {
    crate::args::read_target(
        args.target
            .as_ref()
            .context("--target is required with --device")?,
        None,
    )
}

/// The camera options every camera of the run takes (pixel format, window, exposure, trigger, timeout); the address
/// is each camera's.
fn camera_options(args: &LiveArgs) -> GenicamOptions {
    GenicamOptions {
        allow_discovery: args.allow_discovery,
        pixel_format: args.pixel_format.map(|f| match f {
            PixelFormatArg::Mono8 => PixelFormatChoice::Mono8,
            PixelFormatArg::Mono12 => PixelFormatChoice::Mono12,
            PixelFormatArg::Mono16 => PixelFormatChoice::Mono16,
            PixelFormatArg::Mono12Packed => PixelFormatChoice::Mono12Packed,
            PixelFormatArg::Mono12p => PixelFormatChoice::Mono12p,
        }),
        roi_size_px: args.roi_size,
        exposure_us: args.exposure_us,
        trigger: match args.trigger {
            TriggerArg::Software => TriggerChoice::Software,
            TriggerArg::FreeRun => TriggerChoice::FreeRun,
        },
        frame_rate_hz: args.frame_rate_hz,
        timeout_s: args.timeout_s,
        ..GenicamOptions::default()
    }
}

/// `roitrack lab bench --fake-camera S`: runs the fake camera for `duration_s` of the scenario's time and returns its
/// figures.
#[cfg(feature = "lab")]
pub fn bench_fake_camera(duration_s: f64) -> Result<super::lab::bench::FakeCameraFigures> {
    if !(duration_s > 0.0 && duration_s.is_finite()) {
        bail!("--fake-camera must be a positive number of seconds, got {duration_s}");
    }
    let scenario = Scenario::new(roitrack::sim::ScenarioKind::Orthoglide, 1);
    let options = LiveOptions {
        duration_s,
        ..LiveOptions::default()
    };
    let report = run_fake(
        &scenario,
        &options,
        1,
        std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false)),
        |_| {},
        &mut |_| {},
    )?;
    if let Some(e) = &report.loop_report.acquisition.stopped_by {
        bail!("the fake camera's run stopped early: {e}");
    }
    let (latency_p50_us, latency_p99_us) = report.timestamp_to_estimate_quantiles_us();
    let grab = roitrack::core::stats::sorted(&report.camera.grab_us);
    Ok(super::lab::bench::FakeCameraFigures {
        rois: report.camera.rois,
        rois_per_s: report.loop_report.rois_per_s(),
        latency_p50_us,
        latency_p99_us,
        grab_p50_us: roitrack::core::stats::quantile(&grab, 0.5),
        grab_p99_us: roitrack::core::stats::quantile(&grab, 0.99),
        moved_fraction: report.camera.moved_fraction(),
    })
}
