//! `roitrack ros2-node` (feature `ros2`): a ROS 2 node that takes blob centroids from the DDS bus
//! (`roitrack_msgs/msg/BlobMeasurements`, as the bags carry on `/roitrack/measurements`), or a camera's images
//! (`sensor_msgs/msg/Image` or `CompressedImage`, with `--image-topic`, tracked by the frame tracker as `track
//! --images` tracks files), tracks them and publishes the estimates as `--ros2` does (see `roitrack_ros::ros2_input`,
//! docs/ros2.md).

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{Context, Result, anyhow};
use clap::Args;
use roitrack::estimators::{Tracker, track};
use roitrack::formats::{EstimateWriter, MeasurementChecks};
use roitrack::ros::BagOptions;
use roitrack_ros::ros2::{Ros2Options, Ros2Publisher};
use roitrack_ros::ros2_input::{
    ImageSubscriber, MeasurementSubscriber, REASONS_KEPT, wait_for_camera_info_with,
};
use roitrack_ros::{InputCounts, LeftOut};

use crate::args::{EstimatorArgs, ShutterArg, TargetArgs};
use crate::commands::detect::PolarityArg;
use crate::ros2_args::Ros2BusArgs;

/// Run as a ROS 2 node: take blob centroids (roitrack_msgs/msg/BlobMeasurements) from the DDS bus, or with
/// --image-topic a camera's images (sensor_msgs/msg/Image: mono8, mono16, bgr8, rgb8; or CompressedImage with
/// --compressed) tracked as `track --images` tracks files, and publish every estimate as `--ros2` does
/// (/roitrack/pose, /roitrack/twist, /roitrack/odometry, /tf, /roitrack/status, /roitrack/camera_info). Runs until
/// Ctrl-C (or SIGTERM), or --idle-s without a message. Malformed messages (arrays of different lengths, non-finite
/// values, ids not of the target, centroids off the image, times going back, big-endian CDR; images of another
/// encoding or size, a step that does not match, an image before any camera info; a rolling-shutter frame that starts
/// before the previous one's blobs were read) are left out whole, named in the log and counted by reason in each
/// /roitrack/status (left_out_encoding, left_out_size, ...); the node goes on.
#[derive(Debug, Args)]
pub struct Ros2NodeArgs {
    /// Options from a ROS 2 parameters file (YAML, as `ros2 run --ros-args --params-file` reads): `roitrack:` (or
    /// `/**:`, `/NS/roitrack:` with --ros2-namespace /NS) then `ros__parameters:` then keys, each an option of this
    /// command with _ for - (`target: target.csv`, `every: 10`, `ros2_interface: [127.0.0.1]`). The command line
    /// overrides the file; an unknown key, a value of the wrong type or out of range, or no `ros__parameters` is an
    /// error naming the file, the key and its line (docs/ros2.md). Default: none.
    #[arg(long, value_name = "FILE.yaml")]
    pub params_file: Option<PathBuf>,
    /// Camera calibration (any format `track --camera` reads). Default: the camera of the first
    /// sensor_msgs/msg/CameraInfo on --camera-info-topic.
    #[arg(long, value_name = "FILE")]
    pub camera: Option<PathBuf>,
    /// Without --camera: the topic of the camera's sensor_msgs/msg/CameraInfo (in --ros2-namespace), subscribed both
    /// best effort (a driver's, beside each image) and reliable, transient local (a latched one, as `--ros2`
    /// publishes it).
    #[arg(
        long,
        value_name = "TOPIC",
        default_value = "/roitrack/camera_info",
        conflicts_with = "camera"
    )]
    pub camera_info_topic: String,
    /// Without --camera: how long to wait for the camera info before giving up (s).
    #[arg(long, value_name = "S", default_value_t = 10.0, conflicts_with = "camera",
          value_parser = crate::ranges::positive_up_to(3600.0, " s", "an hour"))]
    pub camera_info_wait_s: f64,
    #[command(flatten)]
    pub target: TargetArgs,
    /// The topic of the centroids (roitrack_msgs/msg/BlobMeasurements, subscribed reliable: a publisher must offer
    /// reliable), in --ros2-namespace.
    #[arg(long, value_name = "TOPIC", default_value = "/roitrack/measurements")]
    pub measurement_topic: String,
    /// Track the images of this topic (sensor_msgs/msg/Image, in --ros2-namespace) with the frame tracker, as `track
    /// --images` tracks files, instead of centroids from --measurement-topic. Encodings mono8, mono16, bgr8 and rgb8
    /// (made grey). Subscribed reliable (as image_transport publishes), or best effort with --image-best-effort.
    /// Default: none (centroids).
    #[arg(long, value_name = "TOPIC", conflicts_with = "measurement_topic")]
    pub image_topic: Option<String>,
    /// With --image-topic: the topic is sensor_msgs/msg/CompressedImage (PNG, JPEG, any format `track --images`
    /// reads).
    #[arg(long, requires = "image_topic")]
    pub compressed: bool,
    /// With --image-topic: subscribe best effort (a camera driver's sensor-data QoS), not reliable.
    #[arg(long, requires = "image_topic")]
    pub image_best_effort: bool,
    /// With --image-topic: how the camera reads its rows, as `track --shutter`.
    #[arg(long, value_enum, default_value = "global", requires = "image_topic")]
    pub shutter: ShutterArg,
    /// With --shutter rolling: the time between two rows (s), as `track --line-delay-s`. Default: none; required
    /// with --shutter rolling.
    #[arg(long, value_name = "D", requires = "image_topic", value_parser = crate::ranges::within(0.0..=roitrack::core::time::MAX_LINE_DELAY_S, " s", "a 1,000-row frame read in a second"))]
    pub line_delay_s: Option<f64>,
    /// With --shutter rolling: hand on the causal filter's estimates as they come, as `track --no-rs-smoothing`
    /// (else each is held until the two frames after it are tracked).
    #[arg(long, requires = "image_topic")]
    pub no_rs_smoothing: bool,
    /// With --image-topic: the exposure time (s, at most 10), as `track --exposure-s`.
    #[arg(long, default_value_t = 1e-3, requires = "image_topic", value_parser = crate::ranges::within(0.0..=roitrack::core::time::MAX_EXPOSURE_S, " s", "beyond, a moving blob is a streak"))]
    pub exposure_s: f64,
    /// With --image-topic: which blobs to look for, as `track --polarity`.
    #[arg(long, value_enum, default_value = "auto", requires = "image_topic")]
    pub polarity: PolarityArg,
    /// With --image-topic: the nearest and farthest distances (m) the target may be at, as `track --distance-m`.
    /// Default: any size from 7 px to a quarter of the image.
    #[arg(long, num_args = 2, value_names = ["NEAR_M", "FAR_M"], requires = "image_topic", value_parser = crate::ranges::positive_up_to(1e3, " m", "a target seen from a kilometre is a pixel"))]
    pub distance_m: Option<Vec<f64>>,
    /// End when no message has come for S seconds after the first one. Default: run until a signal.
    #[arg(long, value_name = "S", value_parser = crate::ranges::positive_up_to(86_400.0, " s", "a day"))]
    pub idle_s: Option<f64>,
    /// Also write the estimates' poses (TUM) to this file. Default: none.
    #[arg(long, value_name = "P.tum", requires = "twists")]
    pub poses: Option<PathBuf>,
    /// Also write the estimates' twists (CSV) to this file. Default: none.
    #[arg(long, value_name = "T.csv", requires = "poses")]
    pub twists: Option<PathBuf>,
    #[command(flatten)]
    pub bus: Ros2BusArgs,
    /// The camera's frame id, the header frame of every message.
    #[arg(long, default_value = "camera", value_name = "ID")]
    pub frame_id: String,
    /// The target's frame id, the child frame of /tf and of the odometry.
    #[arg(long, default_value = "target", value_name = "ID")]
    pub child_frame_id: String,
    #[command(flatten)]
    pub estimator: EstimatorArgs,
}

pub fn run(args: &Ros2NodeArgs) -> Result<()> {
    let target = args.target.read()?;
    let config = args.estimator.config()?;
    if let (Some(poses), Some(twists)) = (&args.poses, &args.twists) {
        let inputs: Vec<(&str, &std::path::Path)> = [
            ("--camera", args.camera.as_deref()),
            ("--target", Some(args.target.target.as_path())),
            ("--params-file", args.params_file.as_deref()),
        ]
        .into_iter()
        .filter_map(|(name, path)| path.map(|p| (name, p)))
        .collect();
        roitrack::formats::check_output_paths(
            &inputs,
            &[("--poses", poses.as_path()), ("--twists", twists.as_path())],
        )?;
    }
    let options: Ros2Options = args.bus.options()?;
    // The node ends at its next look at the bus and writes its outputs.
    let stop = crate::signals::stop_flag();
    let idle = args.idle_s.map_or(Duration::MAX, Duration::from_secs_f64);
    // The images are subscribed to before the camera info is waited for, so that those that come first are counted.
    let mut images = match &args.image_topic {
        Some(topic) => Some(
            ImageSubscriber::start(
                &options,
                topic,
                args.compressed,
                args.image_best_effort,
                stop.clone(),
                idle,
            )
            .map_err(|e| anyhow!("--image-topic {topic}: {e}"))?,
        ),
        None => None,
    };
    let camera = match &args.camera {
        Some(path) => roitrack::formats::read_camera_file(path, &Default::default())?,
        None => {
            eprintln!(
                "roitrack: waiting up to {} s for the camera info on {}",
                args.camera_info_wait_s, args.camera_info_topic
            );
            wait_for_camera_info_with(
                &options,
                &args.camera_info_topic,
                Duration::from_secs_f64(args.camera_info_wait_s),
                &stop,
                || {
                    if let Some(images) = &mut images {
                        images.discard_waiting();
                    }
                },
            )
            .map_err(|e| anyhow!("--camera-info-topic {}: {e}", args.camera_info_topic))?
        }
    };
    let mut writer = match (&args.poses, &args.twists) {
        (Some(poses), Some(twists)) => Some(EstimateWriter::create(poses, twists, None)?),
        _ => None,
    };
    let bag_options = BagOptions {
        frame_id: args.frame_id.clone(),
        child_frame_id: args.child_frame_id.clone(),
        ..BagOptions::default()
    };
    if let Some(images) = images {
        return run_images(
            args,
            images,
            camera,
            target,
            &options,
            &bag_options,
            writer,
            &stop,
        );
    }
    let checks = MeasurementChecks::new()
        .with_known_ids(target.points().iter().map(|p| p.id))
        .with_image_size(camera.width_px, camera.height_px);
    let mut subscriber = MeasurementSubscriber::start(
        &options,
        &args.measurement_topic,
        checks,
        stop.clone(),
        idle,
    )
    .map_err(|e| anyhow!("--measurement-topic {}: {e}", args.measurement_topic))?;
    let counts = subscriber.counts();
    let mut publisher = start_publisher(
        &options,
        &bag_options,
        &camera,
        &counts,
        "centroids",
        subscriber.topic(),
    )?;
    let mut tracker = Tracker::new(camera, target, config)?;
    let mut estimates = 0u64;
    let tracked = track(&mut tracker, &mut subscriber, |e| -> Result<()> {
        hand_on(e, &mut publisher, &mut writer)?;
        estimates += 1;
        Ok(())
    });
    let report = subscriber.report().clone();
    let published = publisher.finish()?;
    eprintln!(
        "roitrack: {} messages ({} centroids) taken from {}, {} left out ({}); {estimates} estimates, {} published, \
         {} dropped",
        report.messages,
        report.measurements,
        subscriber.topic(),
        counts.total_left_out(),
        counts.summary(),
        published.published,
        published.dropped
    );
    print_reasons(&report.reasons);
    tracked.map_err(|e| anyhow!("tracking: {e}"))?;
    finish(writer, &stop)
}

/// The node's publisher, counting what its subscriber takes and leaves out (`counts`), announced on stderr: it takes
/// `what` (centroids, images) from `topic`.
fn start_publisher(
    options: &Ros2Options,
    bag_options: &BagOptions,
    camera: &roitrack::CameraModel,
    counts: &Arc<InputCounts>,
    what: &str,
    topic: &str,
) -> Result<Ros2Publisher> {
    let publisher = Ros2Publisher::start_counting_inputs(
        options,
        bag_options,
        Some(camera.clone()),
        Arc::clone(counts),
    )
    .map_err(|e| anyhow!("ros2-node: {e}"))?;
    eprintln!(
        "roitrack: {} takes {what} from {topic} and publishes its estimates (Ctrl-C ends it)",
        publisher.description(),
    );
    Ok(publisher)
}

/// Publishes the estimate `e`, and writes it to `writer` if there is one.
fn hand_on(
    e: &roitrack::Estimate,
    publisher: &mut Ros2Publisher,
    writer: &mut Option<EstimateWriter>,
) -> Result<()> {
    publisher.publish_estimate(e)?;
    if let Some(writer) = writer {
        writer.write(e)?;
    }
    Ok(())
}

fn print_reasons(reasons: &[String]) {
    for reason in reasons {
        eprintln!("roitrack: left out: {reason}");
    }
}

/// The outputs committed; a signal acknowledged (the node's normal end).
fn finish(writer: Option<EstimateWriter>, stop: &AtomicBool) -> Result<()> {
    if let Some(writer) = writer {
        writer.finish()?;
    }
    if stop.load(Ordering::SeqCst) {
        // Ended by a signal: the node's normal end, its outputs committed.
        crate::signals::acknowledge();
    }
    Ok(())
}

/// `ros2-node --image-topic`: the images tracked by the frame tracker, with the options and on the stream of `track
/// --images` (the decoding on a thread of its own), every estimate published.
#[allow(clippy::too_many_arguments)]
fn run_images(
    args: &Ros2NodeArgs,
    mut images: ImageSubscriber,
    camera: roitrack::CameraModel,
    target: roitrack::Target,
    options: &Ros2Options,
    bag_options: &BagOptions,
    mut writer: Option<EstimateWriter>,
    stop: &AtomicBool,
) -> Result<()> {
    use roitrack::pipeline::{FrameError, FrameStreamError, FrameTracker};

    let camera = crate::commands::track::frame_camera_of(
        args.shutter,
        args.line_delay_s,
        args.exposure_s,
        camera,
    )?;
    let config = crate::commands::track::frame_config_of(
        &args.estimator,
        args.polarity,
        args.distance_m.as_deref(),
        args.no_rs_smoothing,
    )?;
    images.expect_size(camera.width_px, camera.height_px);
    let counts = images.counts();
    let mut publisher = start_publisher(
        options,
        bag_options,
        &camera,
        &counts,
        "images",
        images.topic(),
    )?;
    let mut tracker =
        FrameTracker::new(camera, target, config).context("invalid tracker options")?;
    let mut estimates = 0u64;
    // Frames the tracker refuses for their time (a rolling shutter's frame that starts before the previous frame's
    // last blob was read): left out, counted and named, and the node goes on. The subscriber has already left out
    // those of another size or with a stamp that goes back, so anything else the tracker refuses stops the node.
    let mut too_close = Vec::new();
    let result = roitrack::pipeline::track_frame_stream_leaving_out(
        &mut tracker,
        |frame| {
            images
                .next_frame(frame)
                .map(Ok::<_, std::convert::Infallible>)
        },
        |_, outcome, _| -> Result<()> {
            if let Some(e) = &outcome.estimate {
                hand_on(e, &mut publisher, &mut writer)?;
                estimates += 1;
            }
            Ok(())
        },
        |info, error| {
            if !matches!(error, FrameError::TimeOrder { .. }) {
                return false;
            }
            counts.left_out(LeftOut::TooClose);
            if too_close.len() < REASONS_KEPT {
                too_close.push(format!("{}: {error}", info.name));
            }
            true
        },
    );
    let report = images.report().clone();
    let published = publisher.finish()?;
    let frames = tracker.report();
    eprintln!(
        "roitrack: {} images taken from {}, {} left out ({}); {} frames tracked, target not found in {}; \
         {estimates} estimates, {} published, {} dropped",
        report.messages,
        images.topic(),
        counts.total_left_out(),
        counts.summary(),
        frames.frames,
        frames.not_found,
        published.published,
        published.dropped
    );
    print_reasons(&report.reasons);
    print_reasons(&too_close);
    if let Err(e) = result {
        return Err(match e {
            FrameStreamError::Source(e) => match e {},
            FrameStreamError::Frame {
                info, source: err, ..
            } => anyhow!("{}: {err}", info.name),
            FrameStreamError::Sink(e) => e,
            FrameStreamError::DecoderPanicked => anyhow!("the decoding thread panicked"),
        }
        .context("tracking the images stopped"));
    }
    finish(writer, stop)
}
