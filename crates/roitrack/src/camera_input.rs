//! One camera's input of any kind turned into its stream of measurements, in time order, on the camera's own clock:
//! a measurements file, a ROI recording (each ROI centroided) or frames (an image folder, a numbered pattern, a glob
//! or a video, measured by the camera's own [`FrameTracker`]); with the feature `ros`, a topic of a ROS 2 bag
//! (recorded centroids, or image frames measured as frames are; several cameras may read topics of one bag). A rig's
//! cameras each give one such stream, and [`crate::estimators::rig::merge_streams`] merges them for the
//! [`crate::estimators::rig::RigTracker`].
//!
//! ```
//! use roitrack::camera_input::{CameraInput, open_camera_input};
//! use roitrack::{CameraModel, Target};
//!
//! // A camera's measurements file that is not there: the error names it.
//! let input = CameraInput::Measurements { path: "no/such/file.csv".into(), time_units: None };
//! let err = open_camera_input(&input, &CameraModel::canonical(), &Target::grid4x4()).err().unwrap();
//! assert!(err.to_string().contains("no/such/file.csv"));
//! ```

use std::collections::VecDeque;
use std::fmt;
use std::path::PathBuf;

use roitrack_core::{CameraModel, Measurement, Target, TimeModel};
use roitrack_estimators::ConfigError;
use roitrack_formats::{
    FormatError, FrameInfo, FrameSource, FrameTiming, MeasurementReader, RoiRecordingReader,
    TimeUnit, TimedMeasurements, open_input,
};
use roitrack_image::{CentroidOptions, Frame, RoiImage, measure_roi};
use roitrack_pipeline::{FrameError, FrameTracker, FrameTrackerConfig};

/// One camera's input: what `roitrack track` takes for a single camera.
#[derive(Debug, Clone)]
pub enum CameraInput {
    /// A measurements CSV (t,id,u,v; `-`: the standard input), its times in `time_units` (`None`: seconds, and
    /// times that look like another unit refused).
    Measurements {
        /// The CSV file (`-`: the standard input).
        path: PathBuf,
        /// The unit of its times (`None`: seconds).
        time_units: Option<TimeUnit>,
    },
    /// A ROI recording, each ROI's blob centroided with `options` and timed by the camera's time model; ROIs whose
    /// blob is rejected give no measurement.
    Rois {
        /// The ROI recording.
        path: PathBuf,
        /// How each ROI's blob is centroided.
        options: CentroidOptions,
    },
    /// Frames, timed by `timing`, measured by a [`FrameTracker`] of the camera (its time model says how the rows
    /// are read) with `config`: each frame gives the measurements of the blobs it found, in time order.
    Images {
        /// An image file, a folder of images or a video.
        source: PathBuf,
        /// How each frame's time is found.
        timing: FrameTiming,
        /// The frame tracker's options.
        config: Box<FrameTrackerConfig>,
    },
    /// The blob centroids recorded on a `roitrack_msgs/msg/BlobMeasurements` topic of a ROS 2 bag, on the camera's
    /// clock (the messages' stamps), checked as a measurements file is.
    #[cfg(feature = "ros")]
    BagMeasurements {
        /// The bag: a `.mcap` file or a rosbag2 folder.
        bag: PathBuf,
        /// The topic.
        topic: String,
    },
    /// The image frames of a `sensor_msgs/msg/Image` or `CompressedImage` topic of a ROS 2 bag, each at its header
    /// stamp, measured by a [`FrameTracker`] of the camera with `config`; every frame must have the camera's size.
    #[cfg(feature = "ros")]
    BagImages {
        /// The bag: a `.mcap` file or a rosbag2 folder.
        bag: PathBuf,
        /// The topic.
        topic: String,
        /// The frame tracker's options.
        config: Box<FrameTrackerConfig>,
    },
}

impl CameraInput {
    /// The file or source read.
    pub fn path(&self) -> &std::path::Path {
        match self {
            Self::Measurements { path, .. } | Self::Rois { path, .. } => path,
            Self::Images { source, .. } => source,
            #[cfg(feature = "ros")]
            Self::BagMeasurements { bag, .. } | Self::BagImages { bag, .. } => bag,
        }
    }

    /// The bag's topic read, for the inputs that are a topic of a ROS 2 bag.
    pub fn topic(&self) -> Option<&str> {
        match self {
            #[cfg(feature = "ros")]
            Self::BagMeasurements { topic, .. } | Self::BagImages { topic, .. } => Some(topic),
            _ => None,
        }
    }

    /// Whether the camera's measurements come from frames, which its own frame tracker measures.
    pub fn is_frames(&self) -> bool {
        match self {
            Self::Images { .. } => true,
            #[cfg(feature = "ros")]
            Self::BagImages { .. } => true,
            _ => false,
        }
    }

    /// The command-line option of this kind of input (`--measurements`, `--rois`, `--images`; a bag's centroids
    /// are given as measurements, its frames as images).
    pub fn option(&self) -> &'static str {
        match self {
            Self::Measurements { .. } => "--measurements",
            #[cfg(feature = "ros")]
            Self::BagMeasurements { .. } => "--measurements",
            Self::Rois { .. } => "--rois",
            Self::Images { .. } => "--images",
            #[cfg(feature = "ros")]
            Self::BagImages { .. } => "--images",
        }
    }
}

/// Why a camera's input could not be opened or read on (the cause of a frame's or the options' error is its
/// [`std::error::Error::source`]).
#[derive(Debug)]
pub enum CameraInputError {
    /// The file or source (its own error names it, and the line or frame).
    Format(FormatError),
    /// The frame tracker refused its options.
    Config(ConfigError),
    /// A frame that could not be processed (its index and name in the source).
    Frame {
        /// The frame's index in the source, from 0.
        index: usize,
        /// The frame's name in the source (its file name, or its number in a video).
        name: String,
        /// Why it could not be processed.
        source: FrameError,
    },
}

impl fmt::Display for CameraInputError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Format(e) => write!(f, "{e}"),
            Self::Config(_) => write!(f, "invalid frame tracker options"),
            Self::Frame { index, name, .. } => write!(f, "frame {index} ({name})"),
        }
    }
}

impl std::error::Error for CameraInputError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            // Transparent: its message is the error's own.
            Self::Format(e) => e.source(),
            Self::Config(e) => Some(e),
            Self::Frame { source, .. } => Some(source),
        }
    }
}

impl From<FormatError> for CameraInputError {
    fn from(e: FormatError) -> Self {
        Self::Format(e)
    }
}

/// A camera's measurements in time order (own clock), each checked: a known point, on the camera's image.
pub type MeasurementStream = Box<dyn Iterator<Item = Result<Measurement, CameraInputError>>>;

/// Opens `input` of `camera` showing `target` as its stream of measurements. Frames get their own
/// [`FrameTracker`], whose camera is `camera` (set its time model for the shutter and exposure first).
pub fn open_camera_input(
    input: &CameraInput,
    camera: &CameraModel,
    target: &Target,
) -> Result<MeasurementStream, CameraInputError> {
    let known_ids: Vec<u32> = target.points().iter().map(|p| p.id).collect();
    match input {
        CameraInput::Measurements { path, time_units } => {
            let reader = MeasurementReader::from_reader(open_input(path)?, path)?
                .with_known_ids(known_ids)
                .with_image_size(camera.width_px, camera.height_px);
            Ok(Box::new(
                TimedMeasurements::new(reader, *time_units).map(|m| m.map_err(Into::into)),
            ))
        }
        CameraInput::Rois { path, options } => {
            let reader = RoiRecordingReader::open(path)?.with_known_ids(known_ids);
            Ok(Box::new(RoiMeasurements {
                images: reader,
                options: *options,
                time: camera.time,
            }))
        }
        CameraInput::Images {
            source,
            timing,
            config,
        } => FrameMeasurements::stream(Frames::files(source, timing)?, camera, target, config),
        #[cfg(feature = "ros")]
        CameraInput::BagMeasurements { bag, topic } => {
            let reader = roitrack_ros::BagMeasurementSource::open(bag, topic)?
                .with_known_ids(known_ids)
                .with_image_size(camera.width_px, camera.height_px);
            Ok(Box::new(reader.map(|m| m.map_err(Into::into))))
        }
        #[cfg(feature = "ros")]
        CameraInput::BagImages { bag, topic, config } => {
            FrameMeasurements::stream(Frames::bag(bag, topic, camera)?, camera, target, config)
        }
    }
}

/// Where a camera's frames come from: image files or a video ([`FrameSource`]), or a topic of a ROS 2 bag (feature
/// `ros`), each frame checked against the camera's size. What `track --images` and a rig's frame cameras read.
///
/// ```
/// use roitrack::camera_input::Frames;
/// use roitrack::formats::FrameTiming;
///
/// // A folder that is not there: the error names it.
/// let err = Frames::files("no/such/frames".as_ref(), &FrameTiming::default()).err().unwrap();
/// assert!(err.to_string().contains("no/such/frames"));
/// ```
pub enum Frames {
    /// Image files or a video.
    Files(FrameSource),
    /// A topic of a ROS 2 bag.
    #[cfg(feature = "ros")]
    Bag(Box<roitrack_ros::BagFrameSource>),
}

impl Frames {
    /// The frames of image files or a video (a folder, a numbered pattern, a glob, a video), timed by `timing`.
    pub fn files(source: &std::path::Path, timing: &FrameTiming) -> Result<Self, FormatError> {
        Ok(Self::Files(FrameSource::open(source, timing)?))
    }

    /// The frames of `topic` of the ROS 2 bag `bag` (a `.mcap` file or a rosbag2 folder), each at its header stamp;
    /// a frame of another size than `camera`'s is an error naming it.
    #[cfg(feature = "ros")]
    pub fn bag(
        bag: &std::path::Path,
        topic: &str,
        camera: &CameraModel,
    ) -> Result<Self, FormatError> {
        let mut frames = roitrack_ros::BagFrameSource::open(bag, topic)?;
        frames.expect_size(camera.width_px, camera.height_px);
        Ok(Self::Bag(Box::new(frames)))
    }

    /// Fills `frame` with the next frame (its time set) and tells which it was; `None` at the end.
    pub fn next_frame(&mut self, frame: &mut Frame) -> Option<Result<FrameInfo, FormatError>> {
        match self {
            Self::Files(source) => source.next_frame(frame),
            #[cfg(feature = "ros")]
            Self::Bag(source) => source.next_frame(frame),
        }
    }

    /// How many frames there are, where the source knows it before reading them (files; not a video or a bag).
    pub fn frame_count(&self) -> Option<usize> {
        match self {
            Self::Files(source) => source.frame_count(),
            #[cfg(feature = "ros")]
            Self::Bag(_) => None,
        }
    }
}

/// The centroids of a ROI recording's images, timed (ROIs whose blob is rejected left out).
struct RoiMeasurements<I> {
    images: I,
    options: CentroidOptions,
    time: TimeModel,
}

impl<I: Iterator<Item = Result<RoiImage, FormatError>>> Iterator for RoiMeasurements<I> {
    type Item = Result<Measurement, CameraInputError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            match self.images.next()? {
                Err(e) => return Some(Err(e.into())),
                Ok(image) => {
                    if let Ok(m) = measure_roi(&image, &self.options, &self.time) {
                        return Some(Ok(m));
                    }
                }
            }
        }
    }
}

/// The measurements of each frame as its frame tracker found them, frame after frame; ends after an error.
struct FrameMeasurements {
    frames: Frames,
    tracker: FrameTracker,
    frame: Frame,
    pending: VecDeque<Measurement>,
    failed: bool,
}

impl FrameMeasurements {
    /// The stream of `frames` measured by a frame tracker of `camera` with `config`.
    fn stream(
        frames: Frames,
        camera: &CameraModel,
        target: &Target,
        config: &FrameTrackerConfig,
    ) -> Result<MeasurementStream, CameraInputError> {
        let tracker = FrameTracker::new(camera.clone(), target.clone(), *config)
            .map_err(CameraInputError::Config)?;
        Ok(Box::new(Self {
            frames,
            tracker,
            frame: Frame::default(),
            pending: VecDeque::new(),
            failed: false,
        }))
    }
}

impl Iterator for FrameMeasurements {
    type Item = Result<Measurement, CameraInputError>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(m) = self.pending.pop_front() {
                return Some(Ok(m));
            }
            if self.failed {
                return None;
            }
            let info = match self.frames.next_frame(&mut self.frame)? {
                Ok(info) => info,
                Err(e) => {
                    self.failed = true;
                    return Some(Err(e.into()));
                }
            };
            if let Err(source) = self.tracker.process(&self.frame) {
                self.failed = true;
                return Some(Err(CameraInputError::Frame {
                    index: info.index,
                    name: info.name,
                    source,
                }));
            }
            self.pending
                .extend(self.tracker.measurements().iter().copied());
        }
    }
}
