//! `--mcap OUT.mcap` on `track`, `demo` and `live`: the estimates also as a ROS 2 bag; `--foxglove [ADDR:PORT]`: the
//! same topics served live to Foxglove; `track --paced`: at the recording's speed; `track --mcap-in BAG
//! --image-topic TOPIC`: the frames of a bag (see `roitrack::ros`, docs/ros2.md). `track --ros2` publishes through
//! the same [`Bag`] ([`Bag::publish_on_ros2`]).

use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{Result, anyhow, bail};
use clap::Args;
use roitrack::camera_input::Frames;
use roitrack::formats::{FormatError, FrameTiming};
use roitrack::image::RoiImage;
use roitrack::ros::{
    BackgroundBag, BagFrameSource, BagMeasurementSource, BagOptions, BagWriter,
    DEFAULT_LIVE_ADDRESS, LiveServer, Pacer,
};
use roitrack::{CameraModel, Estimate, Frame, Measurement, MotionState, Target};

/// The options of the ROS 2 outputs: the bag and the live view.
#[derive(Debug, Args)]
// Every command that takes these also takes --ros2 (`crate::ros2_args::Ros2Args`), which the frame ids go with too.
#[command(group = clap::ArgGroup::new("ros_output").multiple(true).args(["mcap", "foxglove", "ros2"]))]
pub struct McapArgs {
    /// Also write the estimates as a ROS 2 bag in MCAP storage (profile ros2, CDR): /roitrack/pose, /roitrack/twist,
    /// /roitrack/odometry, /tf, /roitrack/status per estimate, /roitrack/camera_info once, and with --images the
    /// frames and the projected target (docs/ros2.md). Written to a temporary and moved into place with the other
    /// outputs when the run succeeds. A run that fails or is interrupted (the first Ctrl-C, SIGTERM, SIGHUP stops it
    /// at its next estimate; a second one ends it at once) leaves the bag at OUT.mcap as it was and keeps the bag up
    /// to its last estimate, readable, as OUT.partial.mcap. Default: no bag.
    #[arg(long, value_name = "OUT.mcap")]
    pub mcap: Option<PathBuf>,
    /// Serve the bag's topics live over the Foxglove WebSocket protocol while tracking: in Foxglove, Open
    /// connection, Foxglove WebSocket, ws://ADDR:PORT (docs/ros2.md). Without a value: 127.0.0.1:8765; port 0: a free
    /// port (printed). A viewer that is slow or absent never holds the tracking back (it misses messages instead).
    /// With `track`, --paced plays a recording at its own speed for the viewer. Default: not served.
    #[arg(
        long,
        value_name = "ADDR:PORT",
        num_args = 0..=1,
        default_missing_value = DEFAULT_LIVE_ADDRESS,
        value_parser = parse_live_address,
    )]
    pub foxglove: Option<SocketAddr>,
    /// With --foxglove: before tracking, wait up to S seconds for a viewer to subscribe to a topic (then start
    /// anyway), so that it sees the run from its start. Default: no wait.
    #[arg(long, value_name = "S", requires = "foxglove", value_parser = parse_wait_s)]
    pub foxglove_wait_s: Option<f64>,
    /// With --mcap, --foxglove or --ros2: the frame id of the estimates' frame, the header frame of every message:
    /// the camera's, or with --rig the rig's. Default: camera (with --rig: rig).
    #[arg(long, value_name = "ID", requires = "ros_output")]
    pub frame_id: Option<String>,
    /// With --mcap, --foxglove or --ros2: the target's frame id, the child frame of /tf and of the odometry.
    #[arg(
        long,
        default_value = "target",
        value_name = "ID",
        requires = "ros_output"
    )]
    pub child_frame_id: String,
    /// With --mcap, on `track --rois` and `demo`: also every ROI image as recorded (demo: of the default estimator's
    /// run), with where it sits on the sensor and the centroid measured in it (/roitrack/roi/image, /roitrack/roi/camera_info, /roitrack/roi/annotations;
    /// docs/ros2.md). Off by default: three messages per ROI, about ten times the bag's size.
    #[arg(long, requires = "mcap")]
    pub mcap_rois: bool,
}

fn parse_live_address(text: &str) -> Result<SocketAddr, String> {
    let text = text.trim();
    let text = match text.strip_prefix("localhost:") {
        Some(port) => format!("127.0.0.1:{port}"),
        None => text.to_string(),
    };
    text.parse().map_err(|_| {
        format!("expected ADDR:PORT, an IP address and a port such as {DEFAULT_LIVE_ADDRESS}")
    })
}

fn parse_wait_s(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(s) if (0.0..=3600.0).contains(&s) => Ok(s),
        _ => Err("expected seconds, a number from 0 to 3600 (an hour)".into()),
    }
}

/// The bag (--mcap), the live view (--foxglove) and the DDS bus (`track --ros2`, [`Bag::publish_on_ros2`]), each if
/// asked for, and whether the bag takes the ROI images (--mcap-rois).
pub struct Bag {
    bag: Option<BackgroundBag>,
    live: Option<LiveServer>,
    ros2: crate::ros2_args::Ros2,
    rois: bool,
}

/// The run stops at its next estimate or frame once a signal came (`crate::signals`), through the error path, which
/// completes the bag (kept as NAME.partial.mcap).
fn check_interrupt(bag: &BackgroundBag) -> Result<(), FormatError> {
    crate::signals::check(bag.path())
}

impl McapArgs {
    /// Opens the bag on a writing thread of its own; `target` is drawn on the frames by each estimate. Refuses
    /// --mcap-rois, which only `track --rois` takes ([`Self::open_for_rois`]).
    pub fn open(&self, camera: Option<&CameraModel>, target: Option<&Target>) -> Result<Bag> {
        if self.mcap_rois {
            bail!(
                "--mcap-rois is for the ROI images of `track --rois` and `demo`: this run has none to write"
            );
        }
        self.open_for_rois(camera, target)
    }

    /// [`Self::open`] for a run from ROI images (`track --rois`, `demo`), which --mcap-rois writes to the bag.
    pub fn open_for_rois(
        &self,
        camera: Option<&CameraModel>,
        target: Option<&Target>,
    ) -> Result<Bag> {
        self.open_with_options(camera, target, &self.bag_options())
    }

    /// [`Self::open_for_rois`] with the frame ids of `options` (a rig's: [`Self::rig_bag_options`]); `camera`
    /// (`None` for a rig) goes to /roitrack/camera_info.
    pub fn open_with_options(
        &self,
        camera: Option<&CameraModel>,
        target: Option<&Target>,
        options: &BagOptions,
    ) -> Result<Bag> {
        let options = options.clone();
        // The live server first: an address that cannot be served fails before the bag is created.
        let live = match self.foxglove {
            Some(address) => {
                let live = LiveServer::start(address, &options, camera.cloned(), target.cloned())
                    .map_err(|e| anyhow!("--foxglove {address}: {e}"))?;
                eprintln!(
                    "roitrack: live view on ws://{} (Foxglove: Open connection, Foxglove WebSocket)",
                    live.address()
                );
                if let Some(wait_s) = self.foxglove_wait_s {
                    eprintln!("roitrack: waiting up to {wait_s} s for a viewer to subscribe");
                    if !live.wait_for_subscriber(Duration::from_secs_f64(wait_s)) {
                        eprintln!("roitrack: no viewer subscribed; tracking anyway");
                    }
                }
                Some(live)
            }
            None => None,
        };
        let bag = match &self.mcap {
            Some(path) => Some(BackgroundBag::spawn(
                BagWriter::create(path, &options, camera.cloned())?,
                target.cloned(),
            )),
            None => None,
        };
        Ok(Bag {
            bag,
            live,
            ros2: crate::ros2_args::Ros2::default(),
            rois: self.mcap_rois,
        })
    }

    /// The frame ids (--frame-id, --child-frame-id) of the bag, the live view and --ros2; the estimates' frame is
    /// `camera` unless --frame-id names it.
    pub fn bag_options(&self) -> BagOptions {
        self.bag_options_in("camera")
    }

    /// [`Self::bag_options`] of a rig's run, whose estimates are in the rig's frame: `rig` unless --frame-id names
    /// it. Such a bag holds no camera info and no centroids (they belong to each camera).
    pub fn rig_bag_options(&self) -> BagOptions {
        self.bag_options_in("rig")
    }

    fn bag_options_in(&self, default_frame_id: &str) -> BagOptions {
        BagOptions {
            frame_id: self
                .frame_id
                .clone()
                .unwrap_or_else(|| default_frame_id.to_string()),
            child_frame_id: self.child_frame_id.clone(),
            ..BagOptions::default()
        }
    }

    /// Whether frames are to be copied for the bag or the live view.
    pub fn wants_frames(&self) -> bool {
        self.mcap.is_some() || self.foxglove.is_some()
    }
}

impl Bag {
    /// Publishes every estimate on the ROS 2 DDS bus too, through `ros2` (started by `Ros2Args::start`; nothing
    /// without --ros2), finished with the bag.
    pub fn publish_on_ros2(&mut self, ros2: crate::ros2_args::Ros2) {
        self.ros2 = ros2;
    }

    /// An estimate, to the live view, the DDS bus and the bag.
    pub fn estimate(&mut self, e: &Estimate) -> Result<(), roitrack::formats::FormatError> {
        if let Some(live) = &mut self.live {
            live.publish_estimate(e)?;
        }
        self.ros2.estimate(e)?;
        match &mut self.bag {
            Some(bag) => {
                check_interrupt(bag)?;
                bag.write_estimate(e)
            }
            None => Ok(()),
        }
    }

    /// A frame, the state of its estimate and the centroids measured in it (drawn on it and written to
    /// /roitrack/measurements).
    pub fn frame(
        &mut self,
        frame: Option<Frame>,
        state: Option<&MotionState>,
        measured: &[Measurement],
    ) -> Result<(), roitrack::formats::FormatError> {
        let Some(frame) = frame else {
            return Ok(());
        };
        match (&mut self.bag, &mut self.live) {
            (Some(bag), live) => {
                check_interrupt(bag)?;
                if let Some(live) = live {
                    live.publish_frame(frame.clone(), state, measured)?;
                }
                bag.write_frame(frame, state, measured)?;
                bag.write_measurements(measured)
            }
            (None, Some(live)) => live.publish_frame(frame, state, measured),
            (None, None) => Ok(()),
        }
    }

    /// The measurements and estimates of a finished run, in the order they came: the measurements up to each
    /// estimate's time, then the estimate (so that each /roitrack/measurements message holds those of one estimate).
    /// Written whole even after a signal: the run they come from is over, and the bag keeps it (as NAME.partial.mcap
    /// if the command then stops).
    pub fn run(
        &mut self,
        measured: &[Measurement],
        estimates: &[Estimate],
    ) -> Result<(), FormatError> {
        let mut next = 0;
        for e in estimates {
            let end = next
                + measured[next..]
                    .iter()
                    .take_while(|m| m.t_s <= e.t_ref_s)
                    .count();
            self.measurements(&measured[next..end])?;
            next = end;
            if let Some(live) = &mut self.live {
                live.publish_estimate(e)?;
            }
            self.ros2.estimate(e)?;
            if let Some(bag) = &mut self.bag {
                bag.write_estimate(e)?;
            }
        }
        self.measurements(&measured[next..])
    }

    /// Measured centroids, for /roitrack/measurements.
    pub fn measurements(&mut self, measured: &[Measurement]) -> Result<(), FormatError> {
        match &mut self.bag {
            Some(bag) => bag.write_measurements(measured),
            None => Ok(()),
        }
    }

    /// A ROI image and the centroid measured in it: its measurement to /roitrack/measurements, and with
    /// --mcap-rois, the image and its annotations.
    pub fn roi(
        &mut self,
        image: &RoiImage,
        measured: Option<&Measurement>,
    ) -> Result<(), FormatError> {
        if let (Some(bag), Some(m)) = (&mut self.bag, measured) {
            bag.write_measurements(std::slice::from_ref(m))?;
        }
        self.roi_image(image, measured)
    }

    /// With --mcap-rois: a ROI image, its place and its centroid's annotation (not its measurement).
    pub fn roi_image(
        &mut self,
        image: &RoiImage,
        measured: Option<&Measurement>,
    ) -> Result<(), FormatError> {
        match &mut self.bag {
            Some(bag) if self.rois => bag.write_roi(image, measured),
            _ => Ok(()),
        }
    }

    /// Whether the bag takes the ROI images (--mcap-rois).
    pub fn wants_rois(&self) -> bool {
        self.bag.is_some() && self.rois
    }

    pub fn finish(self) -> Result<()> {
        if let Some(bag) = self.bag {
            let path = bag.path().to_path_buf();
            let messages = bag.finish()?;
            eprintln!(
                "roitrack: {messages} messages written to {}",
                path.display()
            );
        }
        if let Some(live) = self.live {
            finish_live(live)?;
        }
        self.ros2.finish()
    }

    /// Takes the live view out, to be fed from another thread while tracking (see `finish_live`); the bag stays.
    pub fn take_live(&mut self) -> Option<LiveServer> {
        self.live.take()
    }
}

/// Stops the live view, saying what it served.
pub fn finish_live(live: LiveServer) -> Result<()> {
    let address = live.address();
    let report = live.finish()?;
    eprintln!(
        "roitrack: live view on ws://{address}: {} estimates and frames, {} while no viewer subscribed, {} \
         published, {} dropped (the publishing thread was behind)",
        report.handed, report.unseen, report.published, report.dropped
    );
    Ok(())
}

/// `track --paced [FACTOR]`: the recording at its own speed.
#[derive(Debug, Args)]
pub struct PaceArgs {
    /// Replay the input at its own speed (FACTOR times it; default 1): each estimate (each frame with --images) is
    /// released when its time, counted from the first one's, has passed on the wall clock, so that a viewer of
    /// --foxglove or a subscriber of --ros2 follows the run as it was recorded. Default: as fast as possible.
    #[arg(long, value_name = "FACTOR", num_args = 0..=1, default_missing_value = "1", value_parser = parse_factor)]
    pub paced: Option<f64>,
}

fn parse_factor(text: &str) -> Result<f64, String> {
    match text.parse::<f64>() {
        Ok(f) if (1e-3..=1e3).contains(&f) => Ok(f),
        _ => Err(
            "expected a speed factor from 0.001 to 1000 (1: real time, 2: twice as fast)".into(),
        ),
    }
}

impl PaceArgs {
    /// The pacer, if --paced was given.
    pub fn pacer(&self) -> Option<Pacer> {
        self.paced.and_then(Pacer::new)
    }
}

/// The options of tracking the frames of a ROS 2 bag (`--mcap-in BAG`, an alias of `--images BAG`).
#[derive(Debug, Args)]
pub struct McapInArgs {
    /// With --mcap-in (or --images) BAG, a .mcap file or a rosbag2 folder: the topic of the frames,
    /// sensor_msgs/msg/Image (mono8, mono16, bgr8, rgb8) or sensor_msgs/msg/CompressedImage; each frame at its header
    /// stamp. Default: none; required with a bag.
    #[arg(long, value_name = "TOPIC")]
    pub image_topic: Option<String>,
    /// With --mcap-in: the sensor_msgs/msg/CameraInfo topic giving the camera when no --camera is given (Default:
    /// camera_info beside the image topic, `/ns/image_raw` -> `/ns/camera_info`); every frame must have its size.
    #[arg(long, value_name = "TOPIC")]
    pub camera_info_topic: Option<String>,
    /// With --mcap-in BAG: instead of frames, replay the blob centroids recorded on this topic
    /// (roitrack_msgs/msg/BlobMeasurements, as `track --mcap` writes to /roitrack/measurements; docs/ros2.md),
    /// tracked as a measurements file would be. The camera from --camera, else from the bag's CameraInfo
    /// (--camera-info-topic, default camera_info beside the topic: /roitrack/camera_info). Default: none.
    #[arg(long, value_name = "TOPIC", conflicts_with = "image_topic")]
    pub measurement_topic: Option<String>,
}

impl McapInArgs {
    /// The topic whose camera info gives the camera (beside the image or measurement topic by default).
    fn info_topic(&self, topic: &str) -> String {
        self.camera_info_topic
            .clone()
            .unwrap_or_else(|| BagFrameSource::camera_info_topic_of(topic))
    }

    /// The recorded measurements to replay: `--mcap-in BAG --measurement-topic TOPIC`, checked against the
    /// target's ids and the camera's image; `None` without --measurement-topic.
    pub fn measurement_replay(
        &self,
        source: Option<&Path>,
        known_ids: Vec<u32>,
        camera: &CameraModel,
    ) -> Result<Option<BagMeasurementSource>> {
        let Some(topic) = &self.measurement_topic else {
            return Ok(None);
        };
        let Some(bag) = source.filter(|s| is_bag(s)) else {
            bail!(
                "--measurement-topic is for the measurements of a ROS 2 bag: --mcap-in BAG (a .mcap file or a rosbag2 folder)"
            );
        };
        Ok(Some(
            BagMeasurementSource::open(bag, topic)?
                .with_known_ids(known_ids)
                .with_image_size(camera.width_px, camera.height_px),
        ))
    }
}

/// Whether a frame source is a ROS 2 bag: a `.mcap` file, or a folder holding one (rosbag2).
pub fn is_bag(source: &Path) -> bool {
    let is_mcap = |p: &Path| p.extension().is_some_and(|x| x == "mcap");
    is_mcap(source)
        || (source.is_dir()
            && std::fs::read_dir(source)
                .map(|entries| entries.flatten().any(|e| is_mcap(&e.path())))
                .unwrap_or(false))
}

/// The camera: from `--camera` when given, else from the CameraInfo of the bag given by --mcap-in.
pub fn camera(
    camera: Option<&crate::args::CameraArgs>,
    source: Option<&Path>,
    mcap_in: &McapInArgs,
) -> Result<CameraModel> {
    if source.is_none() && mcap_in.image_topic.is_some() {
        bail!("--image-topic is for the frames of a bag: --mcap-in BAG");
    }
    if mcap_in.camera_info_topic.is_some()
        && mcap_in.image_topic.is_none()
        && mcap_in.measurement_topic.is_none()
    {
        bail!("--camera-info-topic goes with --image-topic or --measurement-topic");
    }
    match (camera, source, &mcap_in.image_topic) {
        (Some(camera), _, _) => camera.read(),
        (None, Some(bag), Some(image_topic)) if is_bag(bag) => {
            let mut source = BagFrameSource::open(bag, image_topic)?;
            Ok(source.camera_info(&mcap_in.info_topic(image_topic))?)
        }
        (None, Some(bag), None) if is_bag(bag) && mcap_in.measurement_topic.is_some() => {
            let topic = mcap_in.measurement_topic.as_deref().unwrap_or_default();
            Ok(roitrack::ros::read_camera_info(
                bag,
                &mcap_in.info_topic(topic),
            )?)
        }
        _ => bail!(
            "--camera is required (only the frames of a bag, --mcap-in, may take the camera from the bag)"
        ),
    }
}

/// The frames of `source` (`roitrack::camera_input::Frames`): a bag's topic (--image-topic), checked against the
/// camera's size, or files.
pub fn open_frames(
    source: &Path,
    timing: &FrameTiming,
    mcap_in: &McapInArgs,
    camera: &CameraModel,
) -> Result<Frames> {
    if !is_bag(source) {
        if mcap_in.image_topic.is_some() {
            bail!(
                "--image-topic is for a ROS 2 bag (a .mcap file or a rosbag2 folder), and {} is not one",
                source.display()
            );
        }
        return Ok(Frames::files(source, timing)?);
    }
    if timing.timestamps.is_some() || timing.fps.is_some() {
        bail!("--timestamps and --fps are not for a bag: its frames are at their header stamps");
    }
    let Some(topic) = &mcap_in.image_topic else {
        bail!(
            "{} is a ROS 2 bag: give the topic of its frames with --image-topic",
            source.display()
        );
    };
    Ok(Frames::bag(source, topic, camera)?)
}
