//! `track --images`: frames decoded, tracked by the frame tracker and written, and the frame tracker's options.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use roitrack::formats::EstimateWriter;

use crate::args::ShutterArg;
use crate::commands::detect::{PolarityArg, distance_range};

use super::TrackArgs;

/// `track --images`: frames decoded on their own thread, tracked by the frame tracker, one estimate per frame. On an
/// error (an unreadable frame, a timestamps file that does not match), the estimates so far are written, then the
/// error is reported.
pub(super) fn run_frames(
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
pub(super) fn frame_timing(
    args: &TrackArgs,
    timestamps: Option<PathBuf>,
) -> roitrack::formats::FrameTiming {
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

/// The frame tracker's options of `track --images`, from the command line (the same for every camera of a rig).
pub(super) fn frame_config(args: &TrackArgs) -> Result<roitrack::pipeline::FrameTrackerConfig> {
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
pub(super) fn frame_camera(
    args: &TrackArgs,
    camera: roitrack::CameraModel,
) -> Result<roitrack::CameraModel> {
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
