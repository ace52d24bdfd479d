//! `roitrack track`: run an estimator over a measurements file, a ROI recording or frames and write poses (TUM),
//! twists, diagnostics and the full covariance (CSV).

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use clap::Args;
use roitrack::formats::{
    EstimateWriter, FormatError, MeasurementReader, RoiRecordingReader, TimedMeasurements,
    check_output_paths, open_input,
};
use roitrack::image::CentroidOptions;
use roitrack::pipeline::RoiEvent;
use roitrack::{EstimatorReport, Measurement, TrackStatus, Tracker};

use crate::args::{CameraArgs, CameraPath, EstimatorArgs, ShutterArg, TargetArgs, TimeUnitArg};
use crate::commands::detect::{PolarityArg, distance_range};
use crate::ranges;

/// Checked measurements in time order, from a measurements CSV or replayed from a bag: the two differ only in how
/// they are opened.
type MeasurementSource = Box<dyn Iterator<Item = Result<Measurement, FormatError>>>;

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

/// Where every estimate of a one-camera run goes: paced (--paced), then to the files, the bag, the live view and the
/// DDS bus.
struct EstimateSinks {
    writer: EstimateWriter,
    bag: crate::ros::Bag,
    pacer: Option<roitrack::ros::Pacer>,
}

impl EstimateSinks {
    /// The bag (--mcap, --foxglove; with --rois, room for the ROIs) and the DDS node (--ros2) opened for `camera`
    /// beside `writer`. A node that cannot start fails here, before tracking (and --ros2-wait-s waits here for
    /// subscribers).
    fn open(
        args: &TrackArgs,
        camera: &roitrack::CameraModel,
        writer: EstimateWriter,
    ) -> Result<Self> {
        let mut bag = if !args.rois.is_empty() {
            args.ros.open_for_rois(Some(camera), None)?
        } else {
            args.ros.open(Some(camera), None)?
        };
        bag.publish_on_ros2(args.ros2.start(Some(camera), &args.ros.bag_options())?);
        Ok(EstimateSinks {
            writer,
            bag,
            pacer: args.pace.pacer(),
        })
    }

    fn estimate(&mut self, e: &roitrack::Estimate) -> Result<(), FormatError> {
        if let Some(pacer) = &mut self.pacer {
            pacer.wait_until(e.t_ref_s);
        }
        self.writer.write(e).and_then(|()| self.bag.estimate(e))
    }
}

/// The measurements to track and where they come from: replayed from a bag, or read from a CSV; checked either way
/// (known ids, centroids on the camera's image, times in order and, from a CSV, in seconds or converted). `None`
/// without either (a ROI recording instead).
fn open_measurements(
    args: &TrackArgs,
    replay: Option<roitrack::ros::BagMeasurementSource>,
    known_ids: &[u32],
    camera: &roitrack::CameraModel,
) -> Result<Option<(PathBuf, MeasurementSource)>> {
    Ok(match (replay, args.measurements.first()) {
        (Some(source), _) => Some((source.bag().to_path_buf(), Box::new(source))),
        (None, Some(path)) => {
            let reader = MeasurementReader::from_reader(open_input(path)?, path)?
                .with_known_ids(known_ids.iter().copied())
                .with_image_size(camera.width_px, camera.height_px);
            let reader = TimedMeasurements::new(reader, args.time_units.map(Into::into));
            Some((path.clone(), Box::new(reader)))
        }
        (None, None) => None,
    })
}

/// Tracks `source`, read from `path`; each measurement also goes to the bag's /roitrack/measurements. A signal
/// stops the run at the next measurement, through the error path (src/signals.rs).
fn track_measurements(
    tracker: &mut Tracker,
    path: &std::path::Path,
    source: MeasurementSource,
    sinks: &mut EstimateSinks,
    tick: &dyn Fn(usize),
) -> Result<EstimatorReport> {
    // A RefCell: the estimates' sink writes to the bag too.
    let sinks = std::cell::RefCell::new(sinks);
    let measurements = source.enumerate().map(|(k, m)| {
        tick(k);
        crate::signals::check(path)?;
        let m = m?;
        sinks
            .borrow_mut()
            .bag
            .measurements(std::slice::from_ref(&m))?;
        Ok::<_, FormatError>(m)
    });
    let report = roitrack::track(tracker, measurements, |e| sinks.borrow_mut().estimate(e))
        .with_context(|| format!("tracking {} failed", path.display()))?;
    Ok(report)
}

/// Tracks the ROI recording at `path`, each ROI centroided here with `options`; every ROI and what its centroid gave
/// also goes to the bag (its measurement; with --mcap-rois, the image).
fn track_roi_recording(
    tracker: &mut Tracker,
    path: &std::path::Path,
    known_ids: Vec<u32>,
    options: &CentroidOptions,
    time: &roitrack::core::time::TimeModel,
    sinks: &mut EstimateSinks,
    tick: &dyn Fn(usize),
) -> Result<roitrack::pipeline::RoiTrackReport> {
    let reader = RoiRecordingReader::open(path)?.with_known_ids(known_ids);
    let images = reader.enumerate().map(|(k, image)| {
        tick(k);
        crate::signals::check(path)?;
        image
    });
    let report =
        roitrack::pipeline::track_rois_with(tracker, options, time, images, |event| match event {
            RoiEvent::Roi { image, measured } => sinks.bag.roi(image, measured.ok()),
            RoiEvent::Estimate(e) => sinks.estimate(e),
        })
        .with_context(|| format!("tracking {} failed", path.display()))?;
    Ok(report)
}

/// --rois' centroid options: the defaults, without the symmetry check with --no-symmetry-check.
fn centroid_options(args: &TrackArgs) -> CentroidOptions {
    let mut options = CentroidOptions::default();
    if args.no_symmetry_check {
        options.symmetry = None;
    }
    options
}

/// The one-camera run's closing lines on stderr: the ROIs centroided (with --rois), then the measurements, the
/// estimates and the time per measurement.
fn print_one_camera_summary(
    rois: Option<&roitrack::pipeline::RoiTrackReport>,
    report: &EstimatorReport,
    seconds: f64,
) {
    let EstimatorReport {
        measurements,
        estimates,
        ..
    } = report;
    if let Some(rois) = rois {
        eprintln!(
            "roitrack: {} ROIs centroided; rejected: {}",
            rois.rois, rois.rejections
        );
    }
    eprintln!(
        "roitrack: {measurements} measurements -> {} estimates ({} degenerate, {} lost) in {seconds:.3} s ({:.2} us \
         per measurement)",
        estimates.total(),
        estimates.get(TrackStatus::Degenerate),
        estimates.get(TrackStatus::Lost),
        1e6 * seconds / (*measurements).max(1) as f64
    );
}

/// `track --images`: frames decoded on their own thread, tracked by the frame tracker, one estimate per frame. On an
/// error (an unreadable frame, a timestamps file that does not match), the estimates so far are written, then the
/// error is reported.
fn run_frames(
    args: &TrackArgs,
    source: &std::path::Path,
    camera: roitrack::CameraModel,
    target: roitrack::Target,
) -> Result<()> {
    let camera = frame_camera(args, camera)?;
    let config = frame_config(args)?;
    let timing = frame_timing(args, args.timestamps.first().cloned());
    let mut frames = crate::ros::open_frames(source, &timing, &args.mcap_in, &camera)?;
    let (mut bag, copy_frames) = (
        args.ros.open(Some(&camera), Some(&target))?,
        args.ros.wants_frames(),
    );
    // --ros2: the estimates (not the frames) on the DDS bus, as --mcap writes them.
    bag.publish_on_ros2(args.ros2.start(Some(&camera), &args.ros.bag_options())?);
    let mut tracker = roitrack::pipeline::FrameTracker::new(camera, target, config)
        .context("invalid tracker options")?;
    let mut writer =
        EstimateWriter::create(&args.poses, &args.twists, args.diagnostics.as_deref())?
            .with_covariance(args.covariance.as_deref())?;
    let progress = frames_progress(frames.frame_count());
    let mut pacer = args.pace.pacer();
    let start = Instant::now();
    let result = roitrack::pipeline::track_frame_stream(
        &mut tracker,
        // With --mcap, each frame goes to the bag too: a copy travels with its information.
        |frame| {
            frames.next_frame(frame).map(|r| {
                r.map(|info| {
                    (
                        info,
                        std::cell::Cell::new(copy_frames.then(|| frame.clone())),
                    )
                })
            })
        },
        |(info, frame), outcome, measured| {
            progress.inc(1);
            crate::signals::check(source)?;
            if let Some(pacer) = &mut pacer {
                pacer.wait_until(info.t_s);
            }
            bag.frame(
                frame.take(),
                outcome.estimate.as_ref().map(|e| &e.state),
                measured,
            )?;
            match &outcome.estimate {
                Some(e) => writer.write(e).and_then(|()| bag.estimate(e)),
                None => Ok(()),
            }
        },
    );
    progress.finish_and_clear();
    let seconds = start.elapsed().as_secs_f64();
    let report = tracker.report();
    // What was estimated before an error or an interruption is kept, under the outputs' partial names
    // (NAME.partial.EXT; the outputs themselves stay as they were): the files are completed first.
    if result.is_err() && report.estimates > 0 {
        keep_partial_outputs(args);
    }
    let written = if report.estimates > 0 {
        writer.finish().map(|()| true)
    } else {
        Ok(false)
    };
    let bag_finished = bag.finish();
    print_frames_summary(&report, seconds);
    if let Err(e) = result {
        return Err(frame_stream_error(e, source, report.estimates));
    }
    written?;
    bag_finished?;
    if report.estimates == 0 {
        return Err(target_never_found(source, report.frames));
    }
    Ok(())
}

/// The frames' times of `track --images`: the `timestamps` file, else --fps, else a video's own; in --time-units.
fn frame_timing(args: &TrackArgs, timestamps: Option<PathBuf>) -> roitrack::formats::FrameTiming {
    roitrack::formats::FrameTiming {
        timestamps,
        fps: args.fps,
        time_units: args.time_units.map(Into::into),
    }
}

/// No estimate from the `frames` of `source`: what to check, and how to see the blobs of a frame.
fn target_never_found(source: &std::path::Path, frames: usize) -> anyhow::Error {
    anyhow::anyhow!(
        "{}: no estimate from {frames} frames: the target was never found (check --camera, --target, --polarity; \
         `roitrack detect --overlay DIR` on one frame's image writes DIR/<image name>.overlay.png with the blobs \
         seen in it, found or not)",
        source.display(),
    )
}

/// The progress of `track --images` on stderr (drawn only when stderr is a terminal): a bar when the number of
/// frames is known, else a spinner.
fn frames_progress(frame_count: Option<usize>) -> indicatif::ProgressBar {
    match frame_count {
        Some(n) => indicatif::ProgressBar::new(n as u64).with_style(
            indicatif::ProgressStyle::with_template(
                "{bar:30} {human_pos}/{human_len} frames ({per_sec}, {eta} left)",
            )
            .expect("valid progress template"),
        ),
        None => indicatif::ProgressBar::new_spinner().with_style(
            indicatif::ProgressStyle::with_template("{spinner} {human_pos} frames ({per_sec})")
                .expect("valid progress template"),
        ),
    }
}

/// Has every file output of a failed run kept under its partial name (NAME.partial.EXT) once completed.
fn keep_partial_outputs(args: &TrackArgs) {
    for path in [Some(&args.poses), Some(&args.twists)]
        .into_iter()
        .chain([args.diagnostics.as_ref(), args.covariance.as_ref()])
        .flatten()
    {
        roitrack::formats::keep_if_failed(path);
    }
}

/// The frame run's closing line on stderr: frames, estimates, rate, how the target was measured, the polarity.
fn print_frames_summary(report: &roitrack::pipeline::FrameTrackReport, seconds: f64) {
    let polarity = report.polarity.map_or("none", |p| p.name());
    let blend = if report.by_windows > 0 {
        format!(
            "; window centres {:.0} % by the blobs' outlines",
            100.0 * report.outline_weight
        )
    } else {
        String::new()
    };
    eprintln!(
        "roitrack: {} frames -> {} estimates in {seconds:.3} s ({:.0} frames/s); measured in windows {}, whole \
         {}, new tracks {}, target not found in {}; polarity {polarity}{blend}",
        report.frames,
        report.estimates,
        report.frames as f64 / seconds.max(1e-9),
        report.by_windows,
        report.by_full_frame,
        report.restarts,
        report.not_found,
    );
}

/// What stopped a frame run, as the user reads it: the frame at fault if one was, and the `estimates` kept.
fn frame_stream_error<S, K, I>(
    e: roitrack::pipeline::FrameStreamError<S, K, (roitrack::formats::FrameInfo, I)>,
    source: &std::path::Path,
    estimates: usize,
) -> anyhow::Error
where
    S: std::error::Error + Send + Sync + 'static,
    K: std::error::Error + Send + Sync + 'static,
{
    use roitrack::pipeline::FrameStreamError;
    let kept = if estimates > 0 {
        format!(" (the {estimates} estimates before it are kept under the outputs' partial names)")
    } else {
        String::new()
    };
    match e {
        FrameStreamError::Source(e) => anyhow::Error::new(e),
        FrameStreamError::Frame {
            info, source: err, ..
        } => {
            anyhow::anyhow!("frame {} ({}): {err}", info.0.index, info.0.name)
        }
        FrameStreamError::Sink(e) => anyhow::Error::new(e),
        FrameStreamError::DecoderPanicked => anyhow::anyhow!("the decoding thread panicked"),
    }
    .context(format!("tracking {} stopped{kept}", source.display()))
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

/// One camera's input of a rig run, read and checked against that camera.
struct CameraStream {
    camera: usize,
    /// The option and its file or source, for messages: `--images cam1=frames/`.
    label: String,
    reader: roitrack::camera_input::MeasurementStream,
}

/// `--measurements NAME=FILE` (or `--rois`, `--images`) as (name, file); refused without the `=`.
/// `option NAME=FILE` of a rig run: the index of the rig's camera NAME, the name and the file; an error naming the
/// rig's cameras if it has no such camera.
fn rig_camera(
    option: &str,
    value: &std::path::Path,
    rig_path: &std::path::Path,
    rig: &roitrack::estimators::rig::Rig,
) -> Result<(usize, String, PathBuf)> {
    let (name, path) = split_camera_file(option, value)?;
    let Some(c) = rig.index_of(&name) else {
        let names: Vec<&str> = rig.cameras().iter().map(|c| c.name.as_str()).collect();
        bail!(
            "{option} {name}={}: {} has no camera '{name}' (its cameras: {})",
            path.display(),
            rig_path.display(),
            names.join(", ")
        );
    };
    Ok((c, name, path))
}

fn split_camera_file(option: &str, text: &std::path::Path) -> Result<(String, PathBuf)> {
    let text = text.to_string_lossy();
    match text.split_once('=') {
        Some((name, file)) if !name.is_empty() && !file.is_empty() => {
            Ok((name.to_string(), PathBuf::from(file)))
        }
        _ => bail!(
            "{option} {text}: with --rig, give NAME=FILE, the name of a camera of the rig and its input"
        ),
    }
}

/// The frame tracker's options of `track --images`, from the command line (the same for every camera of a rig).
fn frame_config(args: &TrackArgs) -> Result<roitrack::pipeline::FrameTrackerConfig> {
    frame_config_of(
        &args.estimator,
        args.polarity,
        args.distance_m.as_deref(),
        args.no_rs_smoothing,
    )
}

/// The frame tracker's options of `track --images` (and `ros2-node --image-topic`): the estimator's, --polarity,
/// --distance-m, --no-rs-smoothing.
pub(crate) fn frame_config_of(
    estimator: &crate::args::EstimatorArgs,
    polarity: PolarityArg,
    distance_m: Option<&[f64]>,
    no_rs_smoothing: bool,
) -> Result<roitrack::pipeline::FrameTrackerConfig> {
    use roitrack::detect::PhotoOptions;
    use roitrack::pipeline::FrameTrackerConfig;
    Ok(FrameTrackerConfig {
        // Without --adapt or --motion-model, the frame tracker's own defaults: the noise learnt, the process noise as
        // given, constant acceleration.
        tracker: FrameTrackerConfig::frame_estimator(
            estimator.config()?,
            estimator.adaptation(),
            estimator.named_motion_model(),
        ),
        detection: PhotoOptions {
            polarity: polarity.into(),
            distance_range_m: distance_range(distance_m)?,
            ..PhotoOptions::default()
        },
        // Densities given are the user's, kept whatever the shutter (even equal to the global-shutter defaults).
        jerk_psd_given: estimator.jerk_psd.is_some() || estimator.angular_jerk_psd.is_some(),
        rs_smoothing: !no_rs_smoothing,
        ..FrameTrackerConfig::default()
    })
}

/// The camera model `track --images` tracks frames with: `camera`, read as --shutter and --exposure-s say.
fn frame_camera(args: &TrackArgs, camera: roitrack::CameraModel) -> Result<roitrack::CameraModel> {
    frame_camera_of(args.shutter, args.line_delay_s, args.exposure_s, camera)
}

/// `camera` with the time model of --shutter, --line-delay-s and --exposure-s (`track --images`, `ros2-node
/// --image-topic`).
pub(crate) fn frame_camera_of(
    shutter: ShutterArg,
    line_delay_s: Option<f64>,
    exposure_s: f64,
    mut camera: roitrack::CameraModel,
) -> Result<roitrack::CameraModel> {
    let readout = shutter.readout(line_delay_s)?;
    camera.time = roitrack::core::time::TimeModel {
        readout,
        exposure_s,
    };
    camera
        .time
        .validate()
        .context("invalid --line-delay-s or --exposure-s")?;
    Ok(camera)
}

/// Every camera's input of a rig run (`NAME=...` of --measurements, --rois, --images), by camera: each name a camera
/// of the rig, given once.
fn rig_inputs(
    args: &TrackArgs,
    rig_path: &std::path::Path,
    rig: &roitrack::estimators::rig::Rig,
) -> Result<Vec<Option<roitrack::camera_input::CameraInput>>> {
    use roitrack::camera_input::CameraInput;
    let timestamps = per_camera("--timestamps", &args.timestamps, rig_path, rig)?;
    let topics = per_camera("--topic", &args.topic, rig_path, rig)?;
    let mut inputs: Vec<Option<CameraInput>> = vec![None; rig.len()];
    let given = [
        ("--measurements", &args.measurements),
        ("--rois", &args.rois),
        ("--images", &args.images),
    ];
    for (option, values) in given {
        for value in values {
            let (c, name, path) = rig_camera(option, value, rig_path, rig)?;
            if let Some(before) = &inputs[c] {
                bail!(
                    "{option} {name}={}: camera '{name}' is given twice (also {} {name}={}): one input per camera",
                    path.display(),
                    before.option(),
                    before.path().display()
                );
            }
            let bag = option != "--rois" && crate::ros::is_bag(&path);
            let topic = topics[c].as_ref().map(|t| t.to_string_lossy().into_owned());
            inputs[c] = Some(match (option, bag, topic) {
                (_, true, None) => bail!(
                    "{option} {name}={}: a ROS 2 bag: give camera '{name}''s topic, --topic {name}=TOPIC",
                    path.display()
                ),
                (_, false, Some(topic)) => bail!(
                    "--topic {name}={topic}: camera '{name}''s input ({option} {name}={}) is not a ROS 2 bag (a .mcap \
                     file or a rosbag2 folder)",
                    path.display()
                ),
                ("--measurements", true, Some(topic)) => {
                    CameraInput::BagMeasurements { bag: path, topic }
                }
                ("--images", true, Some(topic)) => CameraInput::BagImages {
                    bag: path,
                    topic,
                    config: Box::new(frame_config(args)?),
                },
                ("--measurements", ..) => CameraInput::Measurements {
                    path,
                    time_units: args.time_units.map(Into::into),
                },
                ("--rois", ..) => CameraInput::Rois {
                    path,
                    options: centroid_options(args),
                },
                _ => CameraInput::Images {
                    source: path,
                    timing: frame_timing(args, timestamps[c].clone()),
                    config: Box::new(frame_config(args)?),
                },
            });
        }
    }
    if let Some((name, path)) = timestamps.iter().enumerate().find_map(|(c, path)| {
        let path = path.as_ref()?;
        let frames = matches!(inputs[c], Some(CameraInput::Images { .. }));
        (!frames).then_some((&rig.cameras()[c].name, path))
    }) {
        bail!(
            "--timestamps {name}={}: camera '{name}' has no --images {name}=..., whose frames' times it would give",
            path.display()
        );
    }
    if let Some((name, topic)) = topics.iter().enumerate().find_map(|(c, topic)| {
        let topic = topic.as_ref()?;
        inputs[c]
            .is_none()
            .then_some((&rig.cameras()[c].name, topic))
    }) {
        bail!(
            "--topic {name}={}: camera '{name}' has no input (--measurements {name}=BAG or --images {name}=BAG)",
            topic.display()
        );
    }
    Ok(inputs)
}

/// Each camera's `option NAME=VALUE` of a rig run (--timestamps, --topic), by camera: each name a camera of the rig,
/// given once.
fn per_camera(
    option: &str,
    values: &[PathBuf],
    rig_path: &std::path::Path,
    rig: &roitrack::estimators::rig::Rig,
) -> Result<Vec<Option<PathBuf>>> {
    let mut per_camera: Vec<Option<PathBuf>> = vec![None; rig.len()];
    for value in values {
        let (c, name, path) = rig_camera(option, value, rig_path, rig)?;
        if let Some(before) = &per_camera[c] {
            bail!(
                "{option} {name}={}: camera '{name}' is given twice (also {option} {name}={})",
                path.display(),
                before.display()
            );
        }
        per_camera[c] = Some(path);
    }
    Ok(per_camera)
}

/// `track --rig`: every camera's input turned into measurements (frames through the camera's own frame tracker) and
/// merged in the order of their rig times (as far as the rig file gives
/// the clocks; the tracker's reorder buffer takes the rest), fused into one pose and twist in the rig's frame.
fn run_rig(args: &TrackArgs, rig_path: &std::path::Path) -> Result<()> {
    check_rig_options(args)?;
    let file = roitrack::formats::read_rig_yaml(rig_path, &Default::default())?;
    let rig = &file.rig;
    let target = args.target.read()?;
    // Each NAME=...: a camera of the rig, once.
    let inputs = rig_inputs(args, rig_path, rig)?;
    if inputs[0].is_none() {
        let first = &rig.cameras()[0].name;
        bail!(
            "the first camera of {}, '{first}', holds the rig's clock: give its input ({first}=FILE to \
             --measurements, --rois or --images)",
            rig_path.display(),
        );
    }
    check_rig_paths(args, rig_path, &file, &inputs)?;
    let streams = open_camera_streams(args, rig, &inputs, &target)?;
    let any_frames = inputs.iter().flatten().any(|i| i.is_frames());
    let mut tracker = rig_tracker(args, rig_path, rig, target, any_frames)?;
    let mut writer =
        EstimateWriter::create(&args.poses, &args.twists, args.diagnostics.as_deref())?
            .with_covariance(args.covariance.as_deref())?;
    // The fused estimates (rig frame, rig clock) also to the bag, the live view and the DDS bus, each if asked.
    let bag_options = args.ros.rig_bag_options();
    let mut bag = args.ros.open_with_options(None, None, &bag_options)?;
    bag.publish_on_ros2(args.ros2.start(None, &bag_options)?);
    let start = Instant::now();
    let (count, estimates) = if tracker.is_single() {
        track_rig_of_one(&mut tracker, streams, rig_path, &mut bag, &mut writer)?
    } else {
        track_merged_streams(&mut tracker, streams, rig_path, rig, &mut bag, &mut writer)?
    };
    writer.finish()?;
    bag.finish()?;
    let clocks = tracker.clocks();
    if let Some(out) = &args.rig_out {
        let calibrations = file.calibrations_for_output(out);
        roitrack::formats::write_rig_yaml(out, rig, &calibrations, Some(&clocks))?;
    }
    let seconds = start.elapsed().as_secs_f64();
    print_learnt_clocks(rig, &clocks);
    let report = tracker.report();
    eprintln!(
        "roitrack: {count} measurements of {} cameras -> {estimates} estimates in {seconds:.3} s ({:.2} us per \
         measurement); fused {}, rejected by the gate {}, fused tracks started {}, instants widened {}",
        rig.len(),
        1e6 * seconds / count.max(1) as f64,
        report.fused,
        report.gated,
        report.starts,
        report.instants_widened
    );
    Ok(())
}

/// Refuses the options a rig run does not take: --camera (the rig gives the cameras), the one-camera bag topics,
/// --mcap-rois.
fn check_rig_options(args: &TrackArgs) -> Result<()> {
    if args.camera.is_some() {
        bail!("--rig gives the cameras: leave out --camera");
    }
    if args.mcap_in.measurement_topic.is_some() || args.mcap_in.image_topic.is_some() {
        bail!(
            "--rig: a camera's bag topic is --topic NAME=TOPIC (not --measurement-topic or --image-topic)"
        );
    }
    if args.ros.mcap_rois {
        bail!("--mcap-rois: a rig's bag holds its fused estimates only");
    }
    Ok(())
}

/// Every given camera's input opened as measurements against its camera (with the time model of --shutter and
/// --exposure-s for frames), in the rig's order, each labelled for messages.
fn open_camera_streams(
    args: &TrackArgs,
    rig: &roitrack::estimators::rig::Rig,
    inputs: &[Option<roitrack::camera_input::CameraInput>],
    target: &roitrack::Target,
) -> Result<Vec<CameraStream>> {
    let mut streams = Vec::new();
    for (c, input) in inputs.iter().enumerate() {
        let Some(input) = input else { continue };
        let name = &rig.cameras()[c].name;
        let label = match input.topic() {
            Some(topic) => format!(
                "{} {name}={} --topic {name}={topic}",
                input.option(),
                input.path().display()
            ),
            None => format!("{} {name}={}", input.option(), input.path().display()),
        };
        let camera = if input.is_frames() {
            frame_camera(args, rig.cameras()[c].camera.clone())?
        } else {
            rig.cameras()[c].camera.clone()
        };
        let reader = roitrack::camera_input::open_camera_input(input, &camera, target)
            .with_context(|| format!("camera '{name}' ({label})"))?;
        streams.push(CameraStream {
            camera: c,
            label,
            reader,
        });
    }
    Ok(streams)
}

/// The rig's tracker, with the frame tracker's estimator options when any camera gives frames. A pose left out of
/// the rig file is the file's fault, not the options': the error names the file.
fn rig_tracker(
    args: &TrackArgs,
    rig_path: &std::path::Path,
    rig: &roitrack::estimators::rig::Rig,
    target: roitrack::Target,
    any_frames: bool,
) -> Result<roitrack::estimators::rig::RigTracker> {
    let config = roitrack::estimators::rig::RigTrackerConfig {
        tracker: if any_frames {
            frame_config(args)?.tracker
        } else {
            args.estimator.config()?
        },
        ..Default::default()
    };
    roitrack::estimators::rig::RigTracker::new(rig.clone(), target, config).map_err(|e| match e {
        roitrack::estimators::rig::RigError::MountUnknown { .. } => {
            anyhow::anyhow!("{}: {e}", rig_path.display())
        }
        e => anyhow::Error::new(e),
    })
}

/// One camera that is the rig: the single-camera path itself (readouts of one time pushed whole). The measurements
/// read and the estimates written.
fn track_rig_of_one(
    tracker: &mut roitrack::estimators::rig::RigTracker,
    mut streams: Vec<CameraStream>,
    rig_path: &std::path::Path,
    bag: &mut crate::ros::Bag,
    writer: &mut EstimateWriter,
) -> Result<(usize, usize)> {
    let mut estimates = 0usize;
    let stream = streams.remove(0);
    let path = stream.label.clone();
    let single = tracker.camera_tracker(0).expect("a rig has a first camera");
    let measurements = stream.reader.map(|m| {
        crate::signals::check(rig_path)?;
        m
    });
    let report = roitrack::track(single, measurements, |e| {
        estimates += 1;
        bag.estimate(e)?;
        writer.write(e)
    })
    .with_context(|| format!("tracking {path} failed"))?;
    let count = report.measurements;
    if report.estimates.total() == 0 {
        bail!(
            "{path}: no estimate from {count} measurements: {}",
            report.why_no_start()
        );
    }
    Ok((count, estimates))
}

/// Several cameras: their measurements merged by the rig file's clocks (or by each camera's own when the file
/// leaves them out) and fused. The measurements read and the estimates written.
fn track_merged_streams(
    tracker: &mut roitrack::estimators::rig::RigTracker,
    streams: Vec<CameraStream>,
    rig_path: &std::path::Path,
    rig: &roitrack::estimators::rig::Rig,
    bag: &mut crate::ros::Bag,
    writer: &mut EstimateWriter,
) -> Result<(usize, usize)> {
    let mut count = 0usize;
    let mut estimates = 0usize;
    let clocks: Vec<roitrack::estimators::rig::ClockModel> =
        rig.cameras().iter().map(|c| c.clock).collect();
    let labels: Vec<String> = streams.iter().map(|s| s.label.clone()).collect();
    let streams_cameras: Vec<usize> = streams.iter().map(|s| s.camera).collect();
    let merged = roitrack::estimators::rig::merge_streams(
        streams.into_iter().map(|s| (s.camera, s.reader)).collect(),
        &clocks,
    );
    for (k, m) in merged {
        crate::signals::check(rig_path)?;
        // k: the stream's position among the streams given.
        let label = &labels[k];
        let m = m.with_context(|| {
            format!(
                "camera '{}' ({label})",
                rig.cameras()[streams_cameras[k]].name
            )
        })?;
        count += 1;
        let fused = tracker
            .push(&m)
            .with_context(|| format!("tracking {label} failed"))?;
        for e in fused {
            bag.estimate(&e.estimate)?;
            writer.write(&e.estimate)?;
            estimates += 1;
        }
    }
    for e in tracker.finish() {
        bag.estimate(&e.estimate)?;
        writer.write(&e.estimate)?;
        estimates += 1;
    }
    if estimates == 0 {
        bail!(
            "{}: no estimate from {count} measurements: no camera's own track started, or no clock offset was found \
             (the target must move)",
            rig_path.display()
        );
    }
    Ok((count, estimates))
}

/// Each clock the rig file left out, as learnt (or not found), on stderr.
fn print_learnt_clocks(
    rig: &roitrack::estimators::rig::Rig,
    clocks: &[roitrack::estimators::rig::ClockEstimate],
) {
    for (camera, clock) in rig.cameras().iter().zip(clocks).skip(1) {
        if !camera.clock_known() {
            eprintln!(
                "roitrack: camera '{}': clock offset {:.6} s ± {:.1} us, drift {:.2} ppm ± {:.2} ppm{}",
                camera.name,
                clock.offset_s,
                clock.offset_sigma_s * 1e6,
                clock.drift_ppm,
                clock.drift_sigma_ppm,
                if clock.synced {
                    ""
                } else {
                    " (not found: the camera was left out)"
                }
            );
        }
    }
}

/// The rig run's inputs (the rig, its calibrations, the target, the measurement files) against its outputs.
fn check_rig_paths(
    args: &TrackArgs,
    rig_path: &std::path::Path,
    file: &roitrack::formats::RigFile,
    given: &[Option<roitrack::camera_input::CameraInput>],
) -> Result<()> {
    let mut inputs = vec![
        ("--target", args.target.target.as_path()),
        ("--rig", rig_path),
    ];
    for path in &file.calibration_paths {
        inputs.push(("--rig's calibration", path.as_path()));
    }
    for input in given.iter().flatten() {
        inputs.push((input.option(), input.path()));
    }
    let mut outputs = vec![
        ("--poses", args.poses.as_path()),
        ("--twists", args.twists.as_path()),
    ];
    for (name, path) in [
        ("--diagnostics", &args.diagnostics),
        ("--covariance", &args.covariance),
        ("--rig-out", &args.rig_out),
    ] {
        if let Some(path) = path {
            outputs.push((name, path.as_path()));
        }
    }
    check_output_paths(&inputs, &outputs)?;
    Ok(())
}
