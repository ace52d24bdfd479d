//! `roitrack track`: run an estimator over a measurements file, a ROI recording or frames and write poses (TUM),
//! twists, diagnostics and the full covariance (CSV).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::Args;
use roitrack::Tracker;
use roitrack::formats::{EstimateWriter, check_output_paths};

use crate::args::{CameraArgs, CameraPath, EstimatorArgs, ShutterArg, TargetArgs, TimeUnitArg};
use crate::commands::detect::PolarityArg;
use crate::ranges;

mod frames;
mod one_camera;
mod rig;

// `ros2-node --image-topic` tracks images with the options of `track --images`.
use frames::run_frames;
#[cfg(feature = "ros2")]
pub(crate) use frames::{frame_camera_of, frame_config_of};
use one_camera::{
    EstimateSinks, centroid_options, open_measurements, print_one_camera_summary,
    track_measurements, track_roi_recording,
};
use rig::run_rig;

/// Track pose and velocity from a measurements file (t,id,u,v), a ROI recording, or frames (an image folder, a
/// numbered pattern, a glob or a video): one pose and one twist per control step (per frame with --images).
#[derive(Debug, Args)]
// --camera may be left out with --mcap-in: the camera is then the bag's CameraInfo (crate::ros::camera).
#[command(mut_arg("camera", |a| a.required(false)))]
pub struct TrackArgs {
    #[command(flatten)]
    pub camera: Option<CameraArgs>,
    #[command(flatten)]
    pub target: TargetArgs,
    /// Measured centroids (CSV t,id,u,v; raw pixels; time order; `-`: the standard input). Centroids that share a time (the blobs of a
    /// global-shutter frame) form one readout: an estimate comes only after the last of them. With --rig, one
    /// NAME=FILE per camera of the rig (repeated), each file on its own camera's clock; a ROS 2 bag's recorded
    /// centroids with --topic NAME=TOPIC. Default: none; this, --rois or --images is required.
    #[arg(long, value_name = "FILE | NAME=FILE", required_unless_present_any = ["rois", "images"])]
    pub measurements: Vec<PathBuf>,
    /// A rig of several cameras (YAML: each camera's name, calibration file relative to the rig file, camera_T_rig as
    /// tx ty tz qx qy qz qw, and optionally its clock_offset_s and clock_drift_ppm; docs/rig.md) instead of --camera:
    /// every camera's input (--measurements, --rois or --images NAME=...) fused into one pose and twist, written in the rig's frame
    /// (rig_T_object) on the rig's clock (the first camera's, unless the file says otherwise). Clocks the file leaves
    /// out are learnt from the measurements (offsets within ±0.1 s). Default: one camera, --camera.
    #[arg(long = "rig", value_name = "RIG.yaml")]
    pub camera_rig: Option<PathBuf>,
    /// With --rig: write the rig file again with every camera's clock as learnt (clock_offset_s, clock_drift_ppm) and
    /// their standard deviations (clock_offset_sigma_s, clock_drift_sigma_ppm; 0 for a clock the file gave).
    /// Default: not written.
    #[arg(long, value_name = "FILE.yaml", requires = "camera_rig")]
    pub rig_out: Option<PathBuf>,
    /// With --rig, for a camera whose input (--measurements NAME=BAG or --images NAME=BAG) is a ROS 2 bag (a .mcap
    /// file or a rosbag2 folder): its topic, NAME=TOPIC (repeated; several cameras may read one bag). Recorded
    /// centroids (roitrack_msgs/msg/BlobMeasurements) with --measurements, sensor_msgs/msg/Image or CompressedImage
    /// with --images; on the camera's own clock (the messages' stamps). Default: none.
    #[arg(long, value_name = "NAME=TOPIC", requires = "camera_rig")]
    pub topic: Vec<PathBuf>,
    /// Instead of centroids: a recording of ROI images (see roitrack_formats::RoiRecordingReader), centroided here.
    /// With --rig, one NAME=FILE per camera (repeated). Default: none.
    #[arg(long, value_name = "FILE | NAME=FILE")]
    pub rois: Vec<PathBuf>,
    /// With --measurements or --timestamps: the unit of the times. Default: seconds, and times more than 0.2 apart
    /// (median over the first 1,000 rows, slower than 5 Hz) or past the year 5000 are refused as likely ms, us or ns
    /// (give s to read them as seconds anyway).
    #[arg(long, value_enum, value_name = "UNIT")]
    pub time_units: Option<TimeUnitArg>,
    /// Instead of centroids: frames. A folder of images (PNG, JPEG, PGM/PPM, TIFF, in natural order: frame2 before
    /// frame10), a numbered pattern (`frames/frame_%05d.png`), a quoted glob (`'frames/*.png'`), or a video (mp4,
    /// mkv, avi, mov, webm; decoded by Debian's `ffmpeg`). One estimate per frame where the target is found.
    /// Also a ROS 2 bag (a .mcap file or a rosbag2 folder; `--mcap-in BAG`) with --image-topic. With --rig, one
    /// NAME=SOURCE per camera (repeated; a bag with --topic NAME=TOPIC), each on its own camera's clock, every
    /// camera with the options below (--fps, --shutter, --polarity...), and its frames' times by --timestamps
    /// NAME=FILE.csv, --fps, a video's own or a bag's stamps. Default: none.
    #[arg(long, value_name = "SOURCE | NAME=SOURCE", visible_alias = "mcap-in")]
    pub images: Vec<PathBuf>,
    /// With --images: the frames' times, a CSV file with a header, a column `t` (s: the mid-exposure time of the
    /// frame's row 0) and one row per frame in order; an optional column `file` must match each frame's file name.
    /// With --rig, one NAME=FILE.csv per camera of --images (repeated), on that camera's own clock. Default: none
    /// (then --fps, or a video's own timestamps).
    #[arg(
        long,
        value_name = "FILE.csv | NAME=FILE.csv",
        requires = "images",
        conflicts_with = "fps"
    )]
    pub timestamps: Vec<PathBuf>,
    /// With --images: frame k is at k / F seconds. Without --timestamps or --fps, only a video's own timestamps are
    /// used; an image sequence without either is refused (roitrack never guesses frame times). Default: none.
    #[arg(long, value_name = "F", requires = "images", value_parser = ranges::within(roitrack::formats::MIN_FRAME_RATE_HZ..=roitrack::formats::MAX_FRAME_RATE_HZ, " Hz", "a frame every 1,000 s to beyond the fastest cameras"))]
    pub fps: Option<f64>,
    /// With --images: how the camera reads its rows. global: every blob of a frame at the frame's time. rolling:
    /// row v is read v * --line-delay-s after row 0, and a blob centred on row v is at t + v * D.
    #[arg(long, value_enum, default_value = "global", requires = "images")]
    pub shutter: ShutterArg,
    /// With --shutter rolling: the time between two rows (s), the sensor's readout time divided by its number of
    /// rows (datasheet, or a calibration); e.g. 30e-6 for 1,024 rows read in 30.7 ms. Default: none; required with
    /// --shutter rolling.
    #[arg(long, value_name = "D", value_parser = ranges::within(0.0..=roitrack::core::time::MAX_LINE_DELAY_S, " s", "a 1,000-row frame read in a second"))]
    pub line_delay_s: Option<f64>,
    /// With --shutter rolling: write the causal filter's estimates as they come, instead of holding each until the
    /// two frames after it are tracked and refitting its pose, at its blobs' row times, with the twist of the poses
    /// around it (the default offline, docs/frames.md "Rolling shutter: offline smoothing": about 3 times closer on
    /// fast motion, two frames of latency).
    #[arg(long, requires = "images")]
    pub no_rs_smoothing: bool,
    /// With --images: the exposure time (s, at most 10), used to size the windows for motion blur.
    #[arg(long, default_value_t = 1e-3, requires = "images", value_parser = ranges::within(0.0..=roitrack::core::time::MAX_EXPOSURE_S, " s", "beyond, a moving blob is a streak"))]
    pub exposure_s: f64,
    /// With --images: which blobs to look for (auto decides on the first frame where the target is found).
    #[arg(long, value_enum, default_value = "auto", requires = "images")]
    pub polarity: PolarityArg,
    /// With --images: the nearest and farthest distances (m) the target may be at, to leave out blobs of impossible
    /// size when searching whole frames (needs diameters in the target file). Default: any size from 7 px to a
    /// quarter of the image.
    #[arg(long, num_args = 2, value_names = ["NEAR_M", "FAR_M"], requires = "images", value_parser = ranges::positive_up_to(1e3, " m", "a target seen from a kilometre is a pixel"))]
    pub distance_m: Option<Vec<f64>>,
    /// With --rois: keep blobs that are not centrally symmetric (by default they are rejected: a reflection or an
    /// occluder merged with a blob biases its centroid by up to half a pixel). For blobs that are not images of disks.
    #[arg(long, requires = "rois")]
    pub no_symmetry_check: bool,
    /// Output poses (TUM: t tx ty tz qx qy qz qw, camera_T_object). Every output may be `-` (the standard output,
    /// for one output at most), a symbolic link (its target is written) or a FIFO (written in place); an output that
    /// is an input, or another output, is refused.
    #[arg(long)]
    pub poses: PathBuf,
    /// Output twists (CSV t,vx,vy,vz,wx,wy,wz): the velocity of the target's origin (m/s) and its angular velocity
    /// (rad/s), both in the camera frame (x right, y down, z forward).
    #[arg(long)]
    pub twists: PathBuf,
    /// Output diagnostics per estimate (CSV: t, status, residual, conditioning, measurements used, iterations, and the
    /// 1-sigma of the position sigma_x_m, sigma_y_m, sigma_z_m (m) and of the velocity sigma_vx_mps, sigma_vy_mps,
    /// sigma_vz_mps (m/s), camera frame: the square roots of the --covariance file's c0_0, c1_1, c2_2 and c6_6, c7_7,
    /// c8_8; NaN where the estimate has no covariance). Default: not written.
    #[arg(long, value_name = "FILE.csv")]
    pub diagnostics: Option<PathBuf>,
    /// Output the full 12x12 covariance per estimate (CSV: t, then the upper triangle c{i}_{j}, i <= j, row by row;
    /// indices 0-11: position (m), rotation vector (rad), velocity (m/s), angular velocity (rad/s), camera frame;
    /// rotation perturbed on the left, R = Exp(w) R_est). NaN entries where the estimate has none (the static
    /// baseline, but for the estimate starting a track; a degenerate window of paper, exact or batch). Default: not
    /// written.
    #[arg(long, value_name = "FILE.csv")]
    pub covariance: Option<PathBuf>,
    #[command(flatten)]
    pub estimator: EstimatorArgs,
    #[command(flatten)]
    pub ros: crate::ros::McapArgs,
    #[command(flatten)]
    pub ros2: crate::ros2_args::Ros2Args,
    #[command(flatten)]
    pub pace: crate::ros::PaceArgs,
    #[command(flatten)]
    pub mcap_in: crate::ros::McapInArgs,
}

pub fn run(args: &TrackArgs) -> Result<()> {
    if let Some(rig) = &args.camera_rig {
        return run_rig(args, rig);
    }
    check_one_camera_inputs(args)?;
    let camera = crate::ros::camera(
        args.camera.as_ref(),
        args.images.first().map(PathBuf::as_path),
        &args.mcap_in,
    )?;
    let target = args.target.read()?;
    if let Some(source) = args.images.first()
        && args.mcap_in.measurement_topic.is_none()
    {
        return run_frames(args, source, camera, target);
    }
    check_no_frame_options(args)?;
    let known_ids: Vec<u32> = target.points().iter().map(|p| p.id).collect();
    let mut tracker = Tracker::new(camera.clone(), target, args.estimator.config()?)
        .context("invalid tracker options")?;
    let writer = EstimateWriter::create(&args.poses, &args.twists, args.diagnostics.as_deref())?
        .with_covariance(args.covariance.as_deref())?;
    // Progress on stderr for long files (drawn only when stderr is a terminal).
    let progress = indicatif::ProgressBar::new_spinner().with_style(
        indicatif::ProgressStyle::with_template(
            "{spinner} {human_pos} inputs tracked ({per_sec}) {elapsed}",
        )
        .expect("valid progress template"),
    );
    let tick = |count: usize| {
        if count.is_multiple_of(4096) {
            progress.set_position(count as u64);
        }
    };
    let replay = args.mcap_in.measurement_replay(
        args.images.first().map(PathBuf::as_path),
        known_ids.clone(),
        &camera,
    )?;
    let mut sinks = EstimateSinks::open(args, &camera, writer)?;
    let start = Instant::now();
    let measurements = open_measurements(args, replay, &known_ids, &camera)?;
    let (path, report, rois) = match (measurements, args.rois.first()) {
        (Some((path, source)), _) => {
            let report = track_measurements(&mut tracker, &path, source, &mut sinks, &tick)?;
            (path, report, None)
        }
        (None, Some(path)) => {
            let options = centroid_options(args);
            let report = track_roi_recording(
                &mut tracker,
                path,
                known_ids,
                &options,
                &camera.time,
                &mut sinks,
                &tick,
            )?;
            (path.clone(), report.estimator, Some(report))
        }
        (None, None) => {
            bail!("give --measurements, --rois or --mcap-in BAG --measurement-topic TOPIC")
        }
    };
    let seconds = start.elapsed().as_secs_f64();
    progress.finish_and_clear();
    if report.estimates.total() == 0 {
        bail!(
            "{}: no estimate from {} measurements: {}",
            path.display(),
            report.measurements,
            report.why_no_start()
        );
    }
    sinks.writer.finish()?;
    sinks.bag.finish()?;
    print_one_camera_summary(rois.as_ref(), &report, seconds);
    Ok(())
}

/// Refuses what only a rig takes (several inputs, or several kinds of input) and options without what they are
/// for, and checks the paths, before anything is read.
fn check_one_camera_inputs(args: &TrackArgs) -> Result<()> {
    if args.measurements.len() > 1 {
        bail!(
            "several --measurements are for the cameras of a rig: give --rig RIG.yaml and NAME=FILE for each"
        );
    }
    for (name, given) in [("--rois", &args.rois), ("--images", &args.images)] {
        if given.len() > 1 {
            bail!(
                "several {name} are for the cameras of a rig: give --rig RIG.yaml and NAME=... for each"
            );
        }
    }
    let kinds = [
        !args.measurements.is_empty(),
        !args.rois.is_empty(),
        !args.images.is_empty(),
    ];
    if kinds.iter().filter(|&&k| k).count() > 1 {
        bail!(
            "give one of --measurements, --rois and --images (several kinds are for the cameras of a rig, --rig)"
        );
    }
    check_paths(args)?;
    if args.timestamps.len() > 1 {
        bail!(
            "--timestamps is given {} times: one file of frame times for --images (one NAME=FILE per camera is for a \
             rig, --rig)",
            args.timestamps.len()
        );
    }
    if args.time_units.is_some() && args.measurements.is_empty() && args.timestamps.is_empty() {
        bail!(
            "--time-units is the unit of the times of --measurements or --timestamps, and neither is given"
        );
    }
    Ok(())
}

/// Refuses the frames' options on measurements (from a file, a ROI recording or replayed from a bag).
fn check_no_frame_options(args: &TrackArgs) -> Result<()> {
    if args.line_delay_s.is_some() {
        bail!("--line-delay-s is for --images with --shutter rolling");
    }
    if !args.timestamps.is_empty() || args.fps.is_some() || args.distance_m.is_some() {
        bail!(
            "--timestamps, --fps and --distance-m are for frames, not for replayed measurements (--measurement-topic)"
        );
    }
    Ok(())
}

/// Refuses, before anything is read or written, outputs (the files, the bag and its partial name) that are inputs
/// (also through symbolic and hard links) or each other, and `-` for more than one output.
fn check_paths(args: &TrackArgs) -> Result<()> {
    let (first_measurements, first_timestamps) = (
        args.measurements.first().cloned(),
        args.timestamps.first().cloned(),
    );
    let (first_rois, first_images) = (args.rois.first().cloned(), args.images.first().cloned());
    let mut inputs = vec![("--target", args.target.target.as_path())];
    if let Some(camera) = args.camera.camera_path() {
        inputs.push(("--camera", camera));
    }
    for (name, path) in [
        ("--measurements", &first_measurements),
        ("--rois", &first_rois),
        ("--images", &first_images),
        ("--timestamps", &first_timestamps),
    ] {
        if let Some(path) = path {
            inputs.push((name, path.as_path()));
        }
    }
    let mut outputs = vec![
        ("--poses", args.poses.clone()),
        ("--twists", args.twists.clone()),
    ];
    for (name, path) in [
        ("--diagnostics", &args.diagnostics),
        ("--covariance", &args.covariance),
        ("--mcap", &args.ros.mcap),
    ] {
        if let Some(path) = path {
            outputs.push((name, path.clone()));
        }
    }
    // What a failed run keeps: the bag up to its last estimate, and with --images the files (NAME.partial.EXT).
    if let Some(mcap) = &args.ros.mcap {
        outputs.push((
            "--mcap's partial bag",
            roitrack::formats::partial_path(mcap),
        ));
    }
    let outputs: Vec<(&str, &std::path::Path)> =
        outputs.iter().map(|(n, p)| (*n, p.as_path())).collect();
    check_output_paths(&inputs, &outputs)?;
    Ok(())
}
