//! # roitrack-ros
//!
//! roitrack's estimates as a ROS 2 bag in MCAP storage, so that they play next to a robot's other topics (`ros2 bag
//! play`), show in Foxglove, and feed a fusion node with their covariances: [`BagWriter`] writes
//! `/roitrack/pose` (`geometry_msgs/msg/PoseWithCovarianceStamped`), `/roitrack/twist`
//! (`geometry_msgs/msg/TwistWithCovarianceStamped`, camera frame), `/roitrack/odometry` (`nav_msgs/msg/Odometry`,
//! its twist in the target frame), `/tf` (`tf2_msgs/msg/TFMessage`), `/roitrack/camera_info`
//! (`sensor_msgs/msg/CameraInfo`, once) and `/roitrack/status` (`diagnostic_msgs/msg/DiagnosticArray`), and with
//! frames `/roitrack/image` (`sensor_msgs/msg/Image`) and `/roitrack/annotations`
//! (`foxglove_msgs/msg/ImageAnnotations`).
//!
//! [`LiveServer`] serves the same messages, byte for byte, over the Foxglove WebSocket protocol while tracking (open
//! `ws://127.0.0.1:8765` in Foxglove); [`Pacer`] replays a recording at its own speed so that a viewer can follow it.
//! With the feature `ros2`,
// The two modules exist only with the feature: without it, their names are shown but not linked.
#![cfg_attr(feature = "ros2", doc = "[`ros2::Ros2Publisher`]")]
#![cfg_attr(not(feature = "ros2"), doc = "`ros2::Ros2Publisher`")]
//! publishes the same messages live on the ROS 2 DDS bus, as a ROS 2 node that robots, `ros2 topic echo` and RViz
//! subscribe to, and
#![cfg_attr(feature = "ros2", doc = "[`ros2_input::MeasurementSubscriber`]")]
#![cfg_attr(not(feature = "ros2"), doc = "`ros2_input::MeasurementSubscriber`")]
//! takes blob centroids from it (`roitrack ros2-node`).
//!
//! [`BagFrameSource`] reads the other way: the image frames of a bag's topic, as a timed frame stream, and the camera
//! of its CameraInfo; [`BagMeasurementSource`] replays the blob centroids of `/roitrack/measurements`
//! (`roitrack_msgs/msg/BlobMeasurements`, roitrack's own message, which [`BagWriter::write_measurements`] writes). [`BackgroundBag`] runs a [`BagWriter`] on a thread of its own, beside the tracker. [`convert`]
//! holds the conversions (stamps, quaternions, the covariances in ROS's order and each message's frame), [`msg`] the
//! messages and their definitions. docs/ros2.md documents the bag.
//!
//! ```
//! use roitrack_ros::{BagOptions, BagWriter};
//!
//! let dir = tempfile::tempdir().unwrap();
//! let bag = BagWriter::create(dir.path().join("empty.mcap"), &BagOptions::default(), None).unwrap();
//! assert_eq!(bag.finish().unwrap(), 0);
//! ```
#![deny(missing_docs)]

mod background;
pub mod convert;
mod input_counts;
#[cfg(feature = "live")]
mod live;
mod measurement_reader;
pub mod msg;
mod output;
mod reader;
#[cfg(feature = "ros2")]
pub mod ros2;
#[cfg(feature = "ros2")]
pub mod ros2_input;
mod writer;

pub use background::BackgroundBag;
pub use input_counts::{INPUT_MESSAGES_KEY, InputCounts, LeftOut, status_keys};
#[cfg(feature = "live")]
pub use live::{DEFAULT_LIVE_ADDRESS, LIVE_SUBPROTOCOL, LiveError, LiveReport, LiveServer, Pacer};
pub use measurement_reader::BagMeasurementSource;
pub use reader::{BagFrameSource, IMAGE_ENCODINGS, IMAGE_TYPES, read_camera_info};
pub use writer::{BagOptions, BagWriter, diagnostic_level, topics};
