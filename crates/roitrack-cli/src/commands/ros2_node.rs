//! `roitrack ros2-node` (feature `ros2`): a ROS 2 node that takes blob centroids from the DDS bus
//! (`roitrack_msgs/msg/BlobMeasurements`, as the bags carry on `/roitrack/measurements`), tracks them and publishes
//! the estimates as `--ros2` does (see `roitrack_ros::ros2_input`, docs/ros2.md).

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use anyhow::{Result, anyhow};
use clap::Args;
use roitrack::core::estimator::{Tracker, track};
use roitrack::formats::{EstimateWriter, MeasurementChecks};
use roitrack::ros::BagOptions;
use roitrack_ros::ros2::{Ros2Options, Ros2Publisher};
use roitrack_ros::ros2_input::{MeasurementSubscriber, wait_for_camera_info};

use crate::args::{EstimatorArgs, TargetArgs};
use crate::ros2_args::Ros2BusArgs;

/// Run as a ROS 2 node: take blob centroids (roitrack_msgs/msg/BlobMeasurements) from the DDS bus, track them, and
/// publish every estimate as `--ros2` does (/roitrack/pose, /roitrack/twist, /roitrack/odometry, /tf,
/// /roitrack/status, /roitrack/camera_info). Runs until Ctrl-C (or SIGTERM), or --idle-s without a message.
/// Malformed messages (arrays of different lengths, non-finite values, ids not of the target, centroids off the
/// image, times going back, big-endian CDR) are left out whole, counted and named; the node goes on.
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

/// Raised by the first signal: the node ends at its next look at the bus and writes its outputs.
fn stop_flag() -> Arc<AtomicBool> {
    let stop = Arc::new(AtomicBool::new(false));
    let flag = stop.clone();
    std::thread::spawn(move || {
        while crate::signals::received().is_none() {
            std::thread::sleep(Duration::from_millis(10));
        }
        flag.store(true, Ordering::SeqCst);
    });
    stop
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
    let stop = stop_flag();
    let camera = match &args.camera {
        Some(path) => roitrack::formats::read_camera_file(path, &Default::default())?,
        None => {
            eprintln!(
                "roitrack: waiting up to {} s for the camera info on {}",
                args.camera_info_wait_s, args.camera_info_topic
            );
            wait_for_camera_info(
                &options,
                &args.camera_info_topic,
                Duration::from_secs_f64(args.camera_info_wait_s),
                &stop,
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
    let checks = MeasurementChecks::new()
        .with_known_ids(target.points().iter().map(|p| p.id))
        .with_image_size(camera.width_px, camera.height_px);
    let mut subscriber = MeasurementSubscriber::start(
        &options,
        &args.measurement_topic,
        checks,
        stop.clone(),
        args.idle_s.map_or(Duration::MAX, Duration::from_secs_f64),
    )
    .map_err(|e| anyhow!("--measurement-topic {}: {e}", args.measurement_topic))?;
    let mut publisher = Ros2Publisher::start(&options, &bag_options, Some(camera.clone()))
        .map_err(|e| anyhow!("ros2-node: {e}"))?;
    eprintln!(
        "roitrack: {} takes centroids from {} and publishes its estimates (Ctrl-C ends it)",
        publisher.description(),
        subscriber.topic()
    );
    let mut tracker = Tracker::new(camera, target, config)?;
    let mut estimates = 0u64;
    let tracked = track(&mut tracker, &mut subscriber, |e| -> Result<()> {
        publisher.publish_estimate(e)?;
        if let Some(writer) = &mut writer {
            writer.write(e)?;
        }
        estimates += 1;
        Ok(())
    });
    let report = subscriber.report().clone();
    let published = publisher.finish()?;
    eprintln!(
        "roitrack: {} messages ({} centroids) taken from {}, {} malformed and left out; {estimates} estimates, {} \
         published, {} dropped",
        report.messages,
        report.measurements,
        subscriber.topic(),
        report.malformed,
        published.published,
        published.dropped
    );
    for reason in &report.reasons {
        eprintln!("roitrack: malformed: {reason}");
    }
    tracked.map_err(|e| anyhow!("tracking: {e}"))?;
    if let Some(writer) = writer {
        writer.finish()?;
    }
    if stop.load(Ordering::SeqCst) {
        // Ended by a signal: the node's normal end, its outputs committed.
        crate::signals::acknowledge();
    }
    Ok(())
}
