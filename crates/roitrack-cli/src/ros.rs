//! `--mcap OUT.mcap` on `track` and `demo`: the estimates also as a ROS 2 bag (see `roitrack::ros`, docs/ros2.md).

use std::path::PathBuf;

use anyhow::Result;
use clap::Args;
use roitrack::ros::{BackgroundBag, BagOptions, BagWriter};
use roitrack::{CameraModel, Estimate, Frame, MotionState, Target};

/// The options of the ROS 2 bag output.
#[derive(Debug, Args)]
pub struct McapArgs {
    /// Also write the estimates as a ROS 2 bag in MCAP storage (profile ros2, CDR): /roitrack/pose, /roitrack/twist,
    /// /roitrack/odometry, /tf, /roitrack/status per estimate, /roitrack/camera_info once, and with --images the
    /// frames and the projected target (docs/ros2.md). Completed on every exit path: a failed run leaves a bag
    /// readable up to its last estimate.
    #[arg(long, value_name = "OUT.mcap")]
    pub mcap: Option<PathBuf>,
    /// With --mcap: the camera's frame id, the header frame of every message.
    #[arg(long, default_value = "camera", value_name = "ID")]
    pub frame_id: String,
    /// With --mcap: the target's frame id, the child frame of /tf and of the odometry.
    #[arg(long, default_value = "target", value_name = "ID")]
    pub child_frame_id: String,
}

/// The bag, if --mcap was given.
pub struct Bag(Option<BackgroundBag>);

impl McapArgs {
    /// Opens the bag on a writing thread of its own; `target` is drawn on the frames by each estimate.
    pub fn open(&self, camera: &CameraModel, target: Option<&Target>) -> Result<Bag> {
        let options = BagOptions {
            frame_id: self.frame_id.clone(),
            child_frame_id: self.child_frame_id.clone(),
            ..BagOptions::default()
        };
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
            Some(bag) => bag.write_estimate(e),
            None => Ok(()),
        }
    }

    pub fn frame(
        &mut self,
        frame: Option<Frame>,
        state: Option<&MotionState>,
    ) -> Result<(), roitrack::formats::FormatError> {
        match (&mut self.0, frame) {
            (Some(bag), Some(frame)) => bag.write_frame(frame, state),
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
