//! `--mcap OUT.mcap` on `track` and `demo`: the estimates also as a ROS 2 bag; `track --mcap-in BAG --image-topic
//! TOPIC`: the frames of a bag (see `roitrack::ros`, docs/ros2.md).

use std::path::{Path, PathBuf};

use anyhow::{Result, bail};
use clap::Args;
use roitrack::formats::{FormatError, FrameInfo, FrameSource, FrameTiming};
use roitrack::ros::{BackgroundBag, BagFrameSource, BagOptions, BagWriter};
use roitrack::{CameraModel, Estimate, Frame, MotionState, Target};

/// The options of the ROS 2 bag output.
#[derive(Debug, Args)]
pub struct McapArgs {
    /// Also write the estimates as a ROS 2 bag in MCAP storage (profile ros2, CDR): /roitrack/pose, /roitrack/twist,
    /// /roitrack/odometry, /tf, /roitrack/status per estimate, /roitrack/camera_info once, and with --images the
    /// frames and the projected target (docs/ros2.md). Completed on every exit path: a failed run leaves a bag
    /// readable up to its last estimate; the first Ctrl-C stops the run at its next estimate and completes the bag
    /// (a second one ends the process at once). Default: no bag.
    #[arg(long, value_name = "OUT.mcap")]
    pub mcap: Option<PathBuf>,
    /// With --mcap: the camera's frame id, the header frame of every message.
    #[arg(long, default_value = "camera", value_name = "ID", requires = "mcap")]
    pub frame_id: String,
    /// With --mcap: the target's frame id, the child frame of /tf and of the odometry.
    #[arg(long, default_value = "target", value_name = "ID", requires = "mcap")]
    pub child_frame_id: String,
}

/// The bag, if --mcap was given.
pub struct Bag(Option<BackgroundBag>);

/// Set by the first Ctrl-C (SIGINT) of a run that writes a bag: the run then stops at its next estimate or frame,
/// through the error path, which completes the bag. A second Ctrl-C ends the process at once.
static INTERRUPTED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

#[cfg(unix)]
extern "C" fn on_interrupt(_signal: libc::c_int) {
    INTERRUPTED.store(true, std::sync::atomic::Ordering::SeqCst);
    // SAFETY: signal() is async-signal-safe; it restores the default action for a second Ctrl-C.
    unsafe {
        libc::signal(libc::SIGINT, libc::SIG_DFL);
    }
}

/// Lets the first Ctrl-C stop the run through its error path instead of killing the process (which would leave the
/// bag without its summary).
fn stop_on_interrupt() {
    #[cfg(unix)]
    // SAFETY: installs a handler that only stores to an atomic and calls signal(), both async-signal-safe.
    unsafe {
        let handler: extern "C" fn(libc::c_int) = on_interrupt;
        libc::signal(libc::SIGINT, handler as libc::sighandler_t);
    }
}

fn check_interrupt(bag: &BackgroundBag) -> Result<(), FormatError> {
    if INTERRUPTED.load(std::sync::atomic::Ordering::SeqCst) {
        return Err(FormatError::new(
            bag.path(),
            "interrupted (Ctrl-C): the bag is completed up to the last estimate",
        ));
    }
    Ok(())
}

impl McapArgs {
    /// Opens the bag on a writing thread of its own; `target` is drawn on the frames by each estimate.
    pub fn open(&self, camera: &CameraModel, target: Option<&Target>) -> Result<Bag> {
        let options = BagOptions {
            frame_id: self.frame_id.clone(),
            child_frame_id: self.child_frame_id.clone(),
            ..BagOptions::default()
        };
        if self.mcap.is_some() {
            stop_on_interrupt();
        }
        Ok(Bag(match &self.mcap {
            Some(path) => Some(BackgroundBag::spawn(
                BagWriter::create(path, &options, Some(camera.clone()))?,
                target.cloned(),
            )),
            None => None,
        }))
    }

    /// Whether frames are to be copied for the bag.
    pub fn wants_frames(&self) -> bool {
        self.mcap.is_some()
    }
}

impl Bag {
    pub fn estimate(&mut self, e: &Estimate) -> Result<(), roitrack::formats::FormatError> {
        match &mut self.0 {
            Some(bag) => {
                check_interrupt(bag)?;
                bag.write_estimate(e)
            }
            None => Ok(()),
        }
    }

    pub fn frame(
        &mut self,
        frame: Option<Frame>,
        state: Option<&MotionState>,
    ) -> Result<(), roitrack::formats::FormatError> {
        match (&mut self.0, frame) {
            (Some(bag), Some(frame)) => {
                check_interrupt(bag)?;
                bag.write_frame(frame, state)
            }
            _ => Ok(()),
        }
    }

    pub fn finish(self) -> Result<()> {
        if let Some(bag) = self.0 {
            let path = bag.path().to_path_buf();
            let messages = bag.finish()?;
            eprintln!(
                "roitrack: {messages} messages written to {}",
                path.display()
            );
        }
        Ok(())
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
    #[arg(long, value_name = "TOPIC", requires = "image_topic")]
    pub camera_info_topic: Option<String>,
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
    match (camera, source, &mcap_in.image_topic) {
        (Some(camera), _, _) => camera.read(),
        (None, Some(bag), Some(image_topic)) if is_bag(bag) => {
            let mut source = BagFrameSource::open(bag, image_topic)?;
            let info_topic = mcap_in
                .camera_info_topic
                .clone()
                .unwrap_or_else(|| BagFrameSource::camera_info_topic_of(image_topic));
            Ok(source.camera_info(&info_topic)?)
        }
        _ => bail!(
            "--camera is required (only the frames of a bag, --mcap-in, may take the camera from the bag)"
        ),
    }
}

/// Frames from files (`FrameSource`) or from a bag's topic (`BagFrameSource`).
pub enum Frames {
    Files(FrameSource),
    Bag(Box<BagFrameSource>),
}

impl Frames {
    /// Opens the frames of `source`: a bag's topic (--image-topic), checked against the camera's size, or files.
    pub fn open(
        source: &Path,
        timing: &FrameTiming,
        mcap_in: &McapInArgs,
        camera: &CameraModel,
    ) -> Result<Self> {
        if !is_bag(source) {
            if mcap_in.image_topic.is_some() {
                bail!(
                    "--image-topic is for a ROS 2 bag (a .mcap file or a rosbag2 folder), and {} is not one",
                    source.display()
                );
            }
            return Ok(Self::Files(FrameSource::open(source, timing)?));
        }
        if timing.timestamps.is_some() || timing.fps.is_some() {
            bail!(
                "--timestamps and --fps are not for a bag: its frames are at their header stamps"
            );
        }
        let Some(topic) = &mcap_in.image_topic else {
            bail!(
                "{} is a ROS 2 bag: give the topic of its frames with --image-topic",
                source.display()
            );
        };
        let mut frames = BagFrameSource::open(source, topic)?;
        frames.expect_size(camera.width_px, camera.height_px);
        Ok(Self::Bag(Box::new(frames)))
    }

    pub fn next_frame(&mut self, frame: &mut Frame) -> Option<Result<FrameInfo, FormatError>> {
        match self {
            Self::Files(files) => files.next_frame(frame),
            Self::Bag(bag) => bag.next_frame(frame),
        }
    }

    pub fn frame_count(&self) -> Option<usize> {
        match self {
            Self::Files(files) => files.frame_count(),
            Self::Bag(_) => None,
        }
    }
}
