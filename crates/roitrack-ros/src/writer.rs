//! [`BagWriter`]: a ROS 2 bag in MCAP storage, written as the estimates come.

use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use roitrack_core::{CameraModel, Measurement, MotionState, Target};
use roitrack_estimators::{Estimate, TrackStatus};
use roitrack_formats::{AtomicFile, FormatError};
use roitrack_image::{Frame, RoiImage};

use crate::convert;
use crate::input_counts::{InputCounts, LeftOut};
use crate::msg::{self, Header};
use crate::output::{McapFile, Output};

/// The topics of a roitrack bag.
pub mod topics {
    /// Each estimate's pose of the target in the camera frame, with covariance (`PoseWithCovarianceStamped`).
    pub const POSE: &str = "/roitrack/pose";
    /// Each estimate's twist, with covariance (`TwistWithCovarianceStamped`).
    pub const TWIST: &str = "/roitrack/twist";
    /// Each estimate's pose and twist together (`nav_msgs/msg/Odometry`).
    pub const ODOMETRY: &str = "/roitrack/odometry";
    /// Each estimate's pose as a transform from the camera frame to the target's (`tf2_msgs/msg/TFMessage`).
    pub const TF: &str = "/tf";
    /// The camera's calibration (`sensor_msgs/msg/CameraInfo`).
    pub const CAMERA_INFO: &str = "/roitrack/camera_info";
    /// Each estimate's status, residual and conditioning (`diagnostic_msgs/msg/DiagnosticArray`).
    pub const STATUS: &str = "/roitrack/status";
    /// The frames written, mono8 or mono16 (`sensor_msgs/msg/Image`).
    pub const IMAGE: &str = "/roitrack/image";
    /// Over each frame: the centroids measured and the target projected by the estimate
    /// (`foxglove_msgs/msg/ImageAnnotations`).
    pub const ANNOTATIONS: &str = "/roitrack/annotations";
    /// The blob centroids handed to the estimator ([`crate::msg::BlobMeasurements`]).
    pub const MEASUREMENTS: &str = "/roitrack/measurements";
    /// Each ROI image, as recorded (optional: `track --rois --mcap-rois`).
    pub const ROI_IMAGE: &str = "/roitrack/roi/image";
    /// Beside each ROI image, at its stamp: the camera info with `roi` set to where the ROI sits on the sensor.
    pub const ROI_CAMERA_INFO: &str = "/roitrack/roi/camera_info";
    /// The centroid measured in each ROI, in the ROI image's pixels.
    pub const ROI_ANNOTATIONS: &str = "/roitrack/roi/annotations";
}

/// How the bag is written.
#[derive(Debug, Clone)]
pub struct BagOptions {
    /// The camera's frame: the header frame of every message (default `camera`).
    pub frame_id: String,
    /// The target's frame: the child frame of `/tf` and of the odometry (default `target`).
    pub child_frame_id: String,
    /// Chunk compression: none (the default, as `ros2 bag record`'s: a bag is then written faster than roitrack
    /// tracks), zstd (a few times smaller, but slower than the tracker: docs/ros2.md, "Cost") or lz4.
    pub compression: Option<mcap::Compression>,
}

impl Default for BagOptions {
    fn default() -> Self {
        Self {
            frame_id: "camera".into(),
            child_frame_id: "target".into(),
            compression: None,
        }
    }
}

/// QoS of a channel as rosbag2 records it (`offered_qos_profiles`): reliable, volatile, or transient local for a
/// latched topic (camera info), with the infinite deadline, lifespan and lease of ROS 2 Humble's bags.
fn offered_qos_profiles(transient_local: bool) -> String {
    let infinite = "\n    sec: 2147483647\n    nsec: 4294967295";
    format!(
        "- history: 3\n  depth: 0\n  reliability: 1\n  durability: {}\n  deadline:{infinite}\n  lifespan:{infinite}\n  \
         liveliness: 1\n  liveliness_lease_duration:{infinite}\n  avoid_ros_namespace_conventions: false\n",
        if transient_local { 1 } else { 2 }
    )
}

#[derive(Debug, Clone, Copy)]
struct Channel {
    id: u16,
    sequence: u32,
}

/// Writes a ROS 2 bag in MCAP storage (profile `ros2`, CDR messages, `ros2msg` schemas, QoS profiles in the channel
/// metadata), readable by `ros2 bag play`, Foxglove, `rosbags` and `mcap`.
///
/// Per estimate ([`write_estimate`](Self::write_estimate)): `/roitrack/pose`, `/roitrack/twist`,
/// `/roitrack/odometry`, `/tf` and `/roitrack/status`, stamped with the estimate's time; `/roitrack/camera_info`
/// once, before the first message. With frames, `/roitrack/image` and `/roitrack/annotations`
/// ([`write_frame`](Self::write_frame)). docs/ros2.md says what each field holds.
///
/// The bag is written to a temporary file beside its path ([`AtomicFile`]), completed (its chunks, summary and index)
/// and moved into place by [`finish`](Self::finish), and also when the writer is dropped on any other exit path (an
/// error, a panic): what was written up to then stays readable. While a run's
/// [`OutputSet`](roitrack_formats::OutputSet) is open, the move waits for its commit; if the run fails, a bag that
/// holds at least one estimate is kept as `NAME.partial.mcap` ([`roitrack_formats::partial_path`]) and the bag at its
/// path stays as it was.
///
/// ```
/// use roitrack_ros::{BagOptions, BagWriter};
/// use roitrack_estimators::{Estimate, TrackStatus};
/// use roitrack_core::{CameraModel, MotionState};
///
/// let dir = tempfile::tempdir().unwrap();
/// let path = dir.path().join("run.mcap");
/// let mut bag = BagWriter::create(&path, &BagOptions::default(), Some(CameraModel::canonical())).unwrap();
/// let state = MotionState::at_rest(Default::default(), nalgebra::Vector3::new(0.0, 0.0, 0.6));
/// let estimate = Estimate {
///     t_ref_s: 0.5, state, residual_rms_px: 0.1, inverse_condition: 0.2, measurements_used: 16,
///     iterations: 1, status: TrackStatus::Tracking, covariance: None, noise_px: 0.1, acceleration: None,
/// };
/// bag.write_estimate(&estimate).unwrap();
/// assert_eq!(bag.finish().unwrap(), 6); // pose, twist, odometry, tf, status and the camera info
/// ```
pub struct BagWriter {
    path: PathBuf,
    writer: Output,
    options: BagOptions,
    camera: Option<CameraModel>,
    camera_info_written: bool,
    pose: Channel,
    twist: Channel,
    odometry: Channel,
    tf: Channel,
    status: Channel,
    camera_info: Option<Channel>,
    image: Option<Channel>,
    annotations: Option<Channel>,
    measurements: Option<Channel>,
    /// `/roitrack/roi/image`, `/roitrack/roi/camera_info`, `/roitrack/roi/annotations`.
    roi_channels: [Option<Channel>; 3],
    /// The columns of a measurements message, reused.
    columns: Columns,
    buffer: Vec<u8>,
    bytes: Vec<u8>,
    text: String,
    messages: u64,
    /// Whether an estimate has been written.
    holds_estimates: bool,
    /// A node's input counts, added to each status ([`count_inputs`](Self::count_inputs)).
    inputs: Option<Arc<InputCounts>>,
}

impl std::fmt::Debug for BagWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BagWriter")
            .field("path", &self.path)
            .field("messages", &self.messages)
            .finish_non_exhaustive()
    }
}

impl BagWriter {
    /// Starts the bag at `path` (replacing a file there when finished). `camera`, if given, is written once to
    /// `/roitrack/camera_info` before the first message.
    pub fn create(
        path: impl AsRef<Path>,
        options: &BagOptions,
        camera: Option<CameraModel>,
    ) -> Result<Self, FormatError> {
        let path = path.as_ref().to_path_buf();
        check_frame_ids(&path, options)?;
        let file = AtomicFile::create(&path)?;
        let writer = mcap::WriteOptions::new()
            .profile("ros2")
            .library(concat!("roitrack ", env!("CARGO_PKG_VERSION")))
            .compression(options.compression)
            // Compressed on the writing thread itself: roitrack runs it beside the tracker (BackgroundBag), and
            // zstd's own workers would compete with both for the cores.
            .compression_threads(0)
            .create(BufWriter::with_capacity(1 << 18, file))
            .map_err(|e| mcap_error(&path, "cannot start the bag", e))?;
        let file = McapFile::new(&path, writer);
        Self::with_output(path, Output::Mcap(file), options, camera)
    }

    /// A writer of the bag's messages to `writer` (the live server's channels, see `LiveServer`), `path` naming it in
    /// errors. Every channel is created here, the camera info's included (on the DDS bus: its publisher, reliable and
    /// transient local, `ros2::qos_of`), before any message: a message can only be written to a [`Channel`] that
    /// `add_channel` gave.
    pub(crate) fn with_output(
        path: PathBuf,
        mut writer: Output,
        options: &BagOptions,
        camera: Option<CameraModel>,
    ) -> Result<Self, FormatError> {
        check_frame_ids(&path, options)?;
        let mut channel = |topic: &str, type_name: &str| -> Result<Channel, FormatError> {
            add_channel(
                &mut writer,
                &path,
                topic,
                type_name,
                topic == topics::CAMERA_INFO,
            )
        };
        let pose = channel(topics::POSE, "geometry_msgs/msg/PoseWithCovarianceStamped")?;
        let twist = channel(
            topics::TWIST,
            "geometry_msgs/msg/TwistWithCovarianceStamped",
        )?;
        let odometry = channel(topics::ODOMETRY, "nav_msgs/msg/Odometry")?;
        let tf = channel(topics::TF, "tf2_msgs/msg/TFMessage")?;
        let status = channel(topics::STATUS, "diagnostic_msgs/msg/DiagnosticArray")?;
        let camera_info = match camera {
            Some(_) => Some(channel(topics::CAMERA_INFO, "sensor_msgs/msg/CameraInfo")?),
            None => None,
        };
        Ok(Self {
            path,
            writer,
            options: options.clone(),
            camera,
            camera_info_written: false,
            pose,
            twist,
            odometry,
            tf,
            status,
            camera_info,
            image: None,
            annotations: None,
            measurements: None,
            roi_channels: [None; 3],
            columns: Columns::default(),
            buffer: Vec::with_capacity(1024),
            bytes: Vec::new(),
            text: String::with_capacity(128),
            messages: 0,
            holds_estimates: false,
            inputs: None,
        })
    }

    /// Adds a node's input counts to each status from now on: the messages it took and those it left out, by reason
    /// ([`status_keys`](crate::status_keys)), as they stand when the status is written.
    pub fn count_inputs(&mut self, counts: Arc<InputCounts>) {
        self.inputs = Some(counts);
    }

    /// The bag's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn stamp(&self, t_s: f64, topic: &str) -> Result<(msg::Time, u64), FormatError> {
        let (Some(stamp), Some(ns)) = (convert::stamp(t_s), convert::nanoseconds(t_s)) else {
            return Err(FormatError::new(
                &self.path,
                format!("time {t_s} s cannot be a ROS stamp (it must be in [0, 2^31) s)"),
            )
            .with_field(topic.to_string()));
        };
        Ok((stamp, ns))
    }

    fn put<T: serde::Serialize>(
        &mut self,
        channel: Channel,
        topic: &str,
        log_time_ns: u64,
        message: &T,
    ) -> Result<Channel, FormatError> {
        self.buffer.clear();
        cdr::serialize_into::<_, _, _, cdr::CdrLe>(&mut self.buffer, message, cdr::Infinite)
            .map_err(|e| {
                FormatError::new(&self.path, format!("cannot serialise: {e}"))
                    .with_field(topic.to_string())
            })?;
        self.writer
            .write_to_known_channel(
                &mcap::records::MessageHeader {
                    channel_id: channel.id,
                    sequence: channel.sequence,
                    log_time: log_time_ns,
                    publish_time: log_time_ns,
                },
                &self.buffer,
            )
            .map_err(|e| mcap_error(&self.path, &format!("cannot write {topic}"), e))?;
        self.messages += 1;
        Ok(Channel {
            id: channel.id,
            sequence: channel.sequence.wrapping_add(1),
        })
    }

    /// Writes the camera info once, at the time of the first message.
    fn camera_info_at(&mut self, t_s: f64) -> Result<(), FormatError> {
        if self.camera_info_written {
            return Ok(());
        }
        let (Some(camera), Some(channel)) = (self.camera.clone(), self.camera_info) else {
            return Ok(());
        };
        let (stamp, ns) = self.stamp(t_s, topics::CAMERA_INFO)?;
        let frame_id = self.options.frame_id.clone();
        let (distortion_model, d) = convert::camera_info_distortion(&camera.distortion);
        let message = camera_info(
            &camera,
            stamp,
            &frame_id,
            distortion_model,
            d,
            msg::RegionOfInterest::default(),
        );
        let channel = self.put(channel, topics::CAMERA_INFO, ns, &message)?;
        self.camera_info = Some(channel);
        self.camera_info_written = true;
        Ok(())
    }

    /// Writes the camera info again at the next message (for a viewer that subscribed to it late).
    #[cfg(feature = "live")]
    pub(crate) fn resend_camera_info(&mut self) {
        self.camera_info_written = false;
    }

    /// Writes one estimate: pose, twist (camera frame), odometry (twist in the target frame), tf and status, all
    /// stamped with the estimate's time.
    pub fn write_estimate(&mut self, estimate: &Estimate) -> Result<(), FormatError> {
        if !self.holds_estimates {
            // From its first estimate on, the bag is worth keeping (as NAME.partial.mcap) if the run fails.
            self.holds_estimates = true;
            if matches!(self.writer, Output::Mcap(_)) {
                roitrack_formats::keep_if_failed(&self.path);
            }
        }
        let t_s = estimate.t_ref_s;
        self.camera_info_at(t_s)?;
        let state = &estimate.state;
        let covariance = estimate.covariance.as_ref();
        let pose = msg::PoseWithCovariance {
            pose: convert::pose(state),
            covariance: msg::Fixed(convert::pose_covariance(covariance)),
        };
        let (linear, angular) = convert::twist_in_camera(state);
        let (object_linear, object_angular) = convert::twist_in_object(state);
        let twist_cam = msg::TwistWithCovariance {
            twist: msg::Twist { linear, angular },
            covariance: msg::Fixed(convert::twist_covariance_in_camera(covariance)),
        };
        let twist_obj = msg::TwistWithCovariance {
            twist: msg::Twist {
                linear: object_linear,
                angular: object_angular,
            },
            covariance: msg::Fixed(convert::twist_covariance_in_object(covariance, state)),
        };
        let (stamp, ns) = self.stamp(t_s, topics::POSE)?;
        // The frame ids are cloned out so that `put` may borrow the writer mutably.
        let (frame_id, child_frame_id) = (
            self.options.frame_id.clone(),
            self.options.child_frame_id.clone(),
        );
        let header = Header {
            stamp,
            frame_id: &frame_id,
        };
        self.pose = self.put(
            self.pose,
            topics::POSE,
            ns,
            &msg::PoseWithCovarianceStamped { header, pose },
        )?;
        self.twist = self.put(
            self.twist,
            topics::TWIST,
            ns,
            &msg::TwistWithCovarianceStamped {
                header,
                twist: twist_cam,
            },
        )?;
        self.odometry = self.put(
            self.odometry,
            topics::ODOMETRY,
            ns,
            &msg::Odometry {
                header,
                child_frame_id: &child_frame_id,
                pose,
                twist: twist_obj,
            },
        )?;
        self.tf = self.put(
            self.tf,
            topics::TF,
            ns,
            &msg::TfMessage {
                transforms: msg::One(msg::TransformStamped {
                    header,
                    child_frame_id: &child_frame_id,
                    transform: pose.pose,
                }),
            },
        )?;
        let mut text = std::mem::take(&mut self.text);
        let (spans, count) = status_values(estimate, self.inputs.as_deref(), &mut text);
        let values = spans.map(|(key, start, end)| msg::KeyValue {
            key,
            value: &text[start..end],
        });
        let values = &values[..count];
        let status = msg::DiagnosticArray {
            header,
            status: msg::One(msg::DiagnosticStatus {
                level: diagnostic_level(estimate.status),
                name: "roitrack",
                message: estimate.status.name(),
                hardware_id: "",
                values: msg::Seq(values),
            }),
        };
        let written = self.put(self.status, topics::STATUS, ns, &status);
        self.text = text;
        self.status = written?;
        self.writer
            .end_of_estimate()
            .map_err(|e| mcap_error(&self.path, "cannot publish the estimate", e))
    }

    /// Writes a frame to `/roitrack/image` (mono8 for 8-bit frames, else mono16, little endian) and its
    /// `/roitrack/annotations`, stamped with the frame's time: the centroids the tracker measured in the frame
    /// (`measured`, green points labelled with their point ids) and, when the frame has an estimate and the bag a
    /// camera, the target's points projected by it (magenta circles of the blobs' diameters where the target has
    /// them, labelled with the ids). A frame with neither gets no annotations message.
    pub fn write_frame(
        &mut self,
        frame: &Frame,
        projection: Option<(&MotionState, &Target)>,
        measured: &[Measurement],
    ) -> Result<(), FormatError> {
        self.camera_info_at(frame.t_s)?;
        let image = match self.image {
            Some(channel) => channel,
            None => add_channel(
                &mut self.writer,
                &self.path,
                topics::IMAGE,
                "sensor_msgs/msg/Image",
                false,
            )?,
        };
        let (stamp, ns) = self.stamp(frame.t_s, topics::IMAGE)?;
        let frame_id = self.options.frame_id.clone();
        let header = Header {
            stamp,
            frame_id: &frame_id,
        };
        let mut bytes = std::mem::take(&mut self.bytes);
        bytes.clear();
        let (encoding, step) = if frame.bit_depth <= 8 {
            bytes.extend(frame.pixels.iter().map(|&p| p.min(255) as u8));
            ("mono8", frame.width)
        } else {
            bytes.extend(frame.pixels.iter().flat_map(|p| p.to_le_bytes()));
            ("mono16", 2 * frame.width)
        };
        let written = self.put(
            image,
            topics::IMAGE,
            ns,
            &msg::Image {
                header,
                height: frame.height,
                width: frame.width,
                encoding,
                is_bigendian: 0,
                step,
                data: msg::Bytes(&bytes),
            },
        );
        self.bytes = bytes;
        self.image = Some(written?);
        let mut annotations = msg::ImageAnnotations {
            circles: Vec::new(),
            points: Vec::new(),
            texts: Vec::new(),
        };
        measured_annotations(measured, stamp, &mut annotations);
        if let (Some((state, target)), Some(camera)) = (projection, self.camera.as_ref()) {
            projected_annotations(camera, target, state, stamp, &mut annotations);
        }
        if annotations.points.is_empty() && annotations.circles.is_empty() {
            return Ok(());
        }
        let annotations_channel = match self.annotations {
            Some(channel) => channel,
            None => add_channel(
                &mut self.writer,
                &self.path,
                topics::ANNOTATIONS,
                "foxglove_msgs/msg/ImageAnnotations",
                false,
            )?,
        };
        self.annotations =
            Some(self.put(annotations_channel, topics::ANNOTATIONS, ns, &annotations)?);
        Ok(())
    }

    /// Writes a batch of measured centroids as one `roitrack_msgs/msg/BlobMeasurements` on `/roitrack/measurements`,
    /// stamped with the time of its first centroid, each centroid's time as its offset from that stamp (so that
    /// `stamp + dt_s` gives it back to within a rounding of the sum). An empty batch writes nothing. Times must be
    /// finite and in [0, 2^31) s.
    ///
    /// ```
    /// use roitrack_core::{CameraModel, Measurement};
    /// use roitrack_ros::{BagMeasurementSource, BagOptions, BagWriter, topics};
    ///
    /// let dir = tempfile::tempdir().unwrap();
    /// let path = dir.path().join("m.mcap");
    /// let mut bag = BagWriter::create(&path, &BagOptions::default(), Some(CameraModel::canonical())).unwrap();
    /// let batch = [
    ///     Measurement { t_s: 0.25, id: 3, u_px: 512.25, v_px: 400.5 },
    ///     Measurement { t_s: 0.25025, id: 4, u_px: 600.0, v_px: 401.0 },
    /// ];
    /// bag.write_measurements(&batch).unwrap();
    /// bag.finish().unwrap();
    /// let read: Vec<Measurement> =
    ///     BagMeasurementSource::open(&path, topics::MEASUREMENTS).unwrap().map(Result::unwrap).collect();
    /// assert_eq!(read.len(), 2);
    /// assert!((read[1].t_s - 0.25025).abs() < 1e-15 && read[1].id == 4 && read[1].u_px == 600.0);
    /// ```
    pub fn write_measurements(&mut self, batch: &[Measurement]) -> Result<(), FormatError> {
        let Some(first) = batch.first() else {
            return Ok(());
        };
        self.camera_info_at(first.t_s)?;
        let channel = match self.measurements {
            Some(channel) => channel,
            None => add_channel(
                &mut self.writer,
                &self.path,
                topics::MEASUREMENTS,
                msg::BLOB_MEASUREMENTS,
                false,
            )?,
        };
        let (stamp, ns) = self.stamp(first.t_s, topics::MEASUREMENTS)?;
        let stamp_s = f64::from(stamp.sec) + 1e-9 * f64::from(stamp.nanosec);
        let mut columns = std::mem::take(&mut self.columns);
        columns.clear();
        for m in batch {
            if !m.t_s.is_finite() {
                self.columns = columns;
                return Err(FormatError::new(
                    &self.path,
                    format!("measurement of point {} at time {} s", m.id, m.t_s),
                )
                .with_field(topics::MEASUREMENTS.to_string()));
            }
            columns.ids.push(m.id);
            columns.u_px.push(m.u_px);
            columns.v_px.push(m.v_px);
            columns.dt_s.push(m.t_s - stamp_s);
        }
        let frame_id = self.options.frame_id.clone();
        let written = self.put(
            channel,
            topics::MEASUREMENTS,
            ns,
            &msg::BlobMeasurements {
                header: Header {
                    stamp,
                    frame_id: &frame_id,
                },
                point_ids: msg::Seq(&columns.ids),
                u_px: msg::Seq(&columns.u_px),
                v_px: msg::Seq(&columns.v_px),
                dt_s: msg::Seq(&columns.dt_s),
                sigma_px: msg::Seq(&[]),
            },
        );
        self.columns = columns;
        self.measurements = Some(written?);
        Ok(())
    }

    /// Writes a ROI image as recorded, stamped with the ROI's time (that of its first row): to `/roitrack/roi/image`
    /// (`mono8` for 8-bit ROIs, else `mono16` little endian, the ROI's own size), with, at the same stamp,
    /// `/roitrack/roi/camera_info` (the bag's camera, with `roi` the window's offset and size on the sensor, ROS's
    /// own way of saying which part of the sensor an image holds; only when the bag has a camera) and
    /// `/roitrack/roi/annotations`: the centroid measured in it (`measured`, in the ROI's pixels: the sensor's less
    /// the window's offset), a green point labelled with the point id, or, for a ROI whose blob was rejected, the
    /// point id and `rejected` in red at its corner.
    pub fn write_roi(
        &mut self,
        image: &RoiImage,
        measured: Option<&Measurement>,
    ) -> Result<(), FormatError> {
        self.camera_info_at(image.t_s)?;
        let (stamp, ns) = self.stamp(image.t_s, topics::ROI_IMAGE)?;
        let frame_id = self.options.frame_id.clone();
        let header = Header {
            stamp,
            frame_id: &frame_id,
        };
        let roi = image.roi;
        if !image.is_consistent() {
            return Err(FormatError::new(
                &self.path,
                format!(
                    "ROI of point {} at {} s: {} pixel values for {} x {} px",
                    image.point_id,
                    image.t_s,
                    image.pixels.len(),
                    roi.width,
                    roi.height
                ),
            )
            .with_field(topics::ROI_IMAGE.to_string()));
        }
        let channel = self.roi_channel(0, topics::ROI_IMAGE, "sensor_msgs/msg/Image")?;
        let mut bytes = std::mem::take(&mut self.bytes);
        bytes.clear();
        let (encoding, step) = if image.bit_depth <= 8 {
            bytes.extend(image.pixels.iter().map(|&p| p.min(255) as u8));
            ("mono8", roi.width)
        } else {
            bytes.extend(image.pixels.iter().flat_map(|p| p.to_le_bytes()));
            ("mono16", 2 * roi.width)
        };
        let written = self.put(
            channel,
            topics::ROI_IMAGE,
            ns,
            &msg::Image {
                header,
                height: roi.height,
                width: roi.width,
                encoding,
                is_bigendian: 0,
                step,
                data: msg::Bytes(&bytes),
            },
        );
        self.bytes = bytes;
        self.roi_channels[0] = Some(written?);
        if let Some(camera) = &self.camera {
            let (distortion_model, d) = convert::camera_info_distortion(&camera.distortion);
            let region = msg::RegionOfInterest {
                x_offset: roi.x0,
                y_offset: roi.y0,
                height: roi.height,
                width: roi.width,
                do_rectify: false,
            };
            let info = camera_info(camera, stamp, &frame_id, distortion_model, d, region);
            let channel =
                self.roi_channel(1, topics::ROI_CAMERA_INFO, "sensor_msgs/msg/CameraInfo")?;
            self.roi_channels[1] = Some(self.put(channel, topics::ROI_CAMERA_INFO, ns, &info)?);
        }
        let mut annotations = msg::ImageAnnotations {
            circles: Vec::new(),
            points: Vec::new(),
            texts: Vec::new(),
        };
        match measured {
            Some(m) => {
                let in_roi = Measurement {
                    u_px: m.u_px - f64::from(roi.x0),
                    v_px: m.v_px - f64::from(roi.y0),
                    ..*m
                };
                measured_annotations(std::slice::from_ref(&in_roi), stamp, &mut annotations);
            }
            None => annotations.texts.push(label(
                format!("{} rejected", image.point_id),
                msg::Point2 { x: 0.0, y: 10.0 },
                REJECTED_COLOR,
                stamp,
            )),
        }
        let channel = self.roi_channel(
            2,
            topics::ROI_ANNOTATIONS,
            "foxglove_msgs/msg/ImageAnnotations",
        )?;
        self.roi_channels[2] =
            Some(self.put(channel, topics::ROI_ANNOTATIONS, ns, &annotations)?);
        Ok(())
    }

    /// The channel `k` of the ROI topics, added when first used.
    fn roi_channel(
        &mut self,
        k: usize,
        topic: &str,
        type_name: &str,
    ) -> Result<Channel, FormatError> {
        match self.roi_channels[k] {
            Some(channel) => Ok(channel),
            None => add_channel(&mut self.writer, &self.path, topic, type_name, false),
        }
    }

    /// Completes the bag (the last chunk, the summary and its index) and says how many messages it holds.
    pub fn finish(mut self) -> Result<u64, FormatError> {
        self.writer
            .finish()
            .map_err(|e| mcap_error(&self.path, "cannot complete the bag", e))?;
        self.writer.close()?;
        Ok(self.messages)
    }
}

/// The columns of a `BlobMeasurements` message.
#[derive(Debug, Default)]
struct Columns {
    ids: Vec<u32>,
    u_px: Vec<f64>,
    v_px: Vec<f64>,
    dt_s: Vec<f64>,
}

impl Columns {
    fn clear(&mut self) {
        self.ids.clear();
        self.u_px.clear();
        self.v_px.clear();
        self.dt_s.clear();
    }
}

/// The camera info of `camera`; `roi`: the part of the sensor an image holds (all zeros: the whole).
fn camera_info<'a>(
    camera: &CameraModel,
    stamp: msg::Time,
    frame_id: &'a str,
    distortion_model: &'a str,
    d: Vec<f64>,
    roi: msg::RegionOfInterest,
) -> msg::CameraInfo<'a> {
    let i = &camera.intrinsics;
    msg::CameraInfo {
        header: Header { stamp, frame_id },
        height: camera.height_px,
        width: camera.width_px,
        distortion_model,
        d,
        k: msg::Fixed([
            i.fx_px, i.skew_px, i.cx_px, 0.0, i.fy_px, i.cy_px, 0.0, 0.0, 1.0,
        ]),
        r: msg::Fixed([1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]),
        p: msg::Fixed([
            i.fx_px, i.skew_px, i.cx_px, 0.0, 0.0, i.fy_px, i.cy_px, 0.0, 0.0, 0.0, 1.0, 0.0,
        ]),
        binning_x: 0,
        binning_y: 0,
        roi,
    }
}

fn add_channel(
    writer: &mut Output,
    path: &Path,
    topic: &str,
    type_name: &str,
    transient_local: bool,
) -> Result<Channel, FormatError> {
    let schema = msg::schema_text(type_name).expect("every type written has a definition");
    let schema_id = writer
        .add_schema(type_name, "ros2msg", schema.as_bytes())
        .map_err(|e| mcap_error(path, "cannot add a schema", e))?;
    let metadata = BTreeMap::from([(
        "offered_qos_profiles".to_string(),
        offered_qos_profiles(transient_local),
    )]);
    let id = writer
        .add_channel(schema_id, topic, "cdr", &metadata)
        .map_err(|e| mcap_error(path, &format!("cannot add the channel {topic}"), e))?;
    Ok(Channel { id, sequence: 0 })
}

fn check_frame_ids(path: &Path, options: &BagOptions) -> Result<(), FormatError> {
    for (field, id) in [
        ("frame_id", &options.frame_id),
        ("child_frame_id", &options.child_frame_id),
    ] {
        if id.is_empty() || id.contains('\0') {
            return Err(FormatError::new(
                path,
                format!("{field} {id:?}: empty or holds a NUL"),
            ));
        }
    }
    Ok(())
}

fn mcap_error(path: &Path, doing: &str, error: mcap::McapError) -> FormatError {
    match error {
        mcap::McapError::Io(io) => FormatError::io(path, doing, io),
        other => FormatError::new(path, format!("{doing}: {other}")),
    }
}

/// The diagnostic level of a status: OK for the statuses roitrack vouches for (converging, tracking), WARN for an
/// estimate that rests on a prediction (degenerate, disputed), ERROR for a lost track.
pub fn diagnostic_level(status: TrackStatus) -> u8 {
    match status {
        TrackStatus::Converging | TrackStatus::Tracking => 0,
        TrackStatus::Degenerate | TrackStatus::Disputed => 1,
        TrackStatus::Lost => 2,
    }
}

/// The most values a status has: the estimate's five and a node's input counts.
const STATUS_VALUES: usize = 5 + 1 + LeftOut::ALL.len();

/// The status values' text, written into one reused buffer: `(key, start, end)` of each value, and how many there are
/// (the estimate's five, then with `inputs` the keys of [`status_keys`](crate::status_keys)).
fn status_values(
    estimate: &Estimate,
    inputs: Option<&InputCounts>,
    text: &mut String,
) -> ([(&'static str, usize, usize); STATUS_VALUES], usize) {
    use std::fmt::Write;
    text.clear();
    let mut spans = [("", 0, 0); STATUS_VALUES];
    let mut count = 0;
    let mut put = |key: &'static str, text: &mut String, value: std::fmt::Arguments<'_>| {
        let start = text.len();
        let _ = text.write_fmt(value);
        spans[count] = (key, start, text.len());
        count += 1;
    };
    put("status", text, format_args!("{}", estimate.status.name()));
    put(
        "residual_rms_px",
        text,
        format_args!("{}", estimate.residual_rms_px),
    );
    put(
        "inverse_condition",
        text,
        format_args!("{}", estimate.inverse_condition),
    );
    put(
        "measurements_used",
        text,
        format_args!("{}", estimate.measurements_used),
    );
    put("iterations", text, format_args!("{}", estimate.iterations));
    if let Some(inputs) = inputs {
        for (key, value) in crate::status_keys().zip(inputs.values()) {
            put(key, text, format_args!("{value}"));
        }
    }
    (spans, count)
}

/// The colour of the measured centroids in the annotations: green.
pub const MEASURED_COLOR: msg::Color = msg::Color {
    r: 0.1,
    g: 0.9,
    b: 0.2,
    a: 1.0,
};
/// The colour of the target's points projected by the estimate: magenta.
pub const PROJECTED_COLOR: msg::Color = msg::Color {
    r: 1.0,
    g: 0.2,
    b: 0.9,
    a: 1.0,
};
/// The colour of the label of a ROI whose blob was rejected: red.
pub const REJECTED_COLOR: msg::Color = msg::Color {
    r: 1.0,
    g: 0.2,
    b: 0.1,
    a: 1.0,
};
const CLEAR: msg::Color = msg::Color {
    r: 0.0,
    g: 0.0,
    b: 0.0,
    a: 0.0,
};
/// Foxglove draws a `POINTS` annotation's points with `thickness` as their diameter (px).
const MEASURED_POINT_PX: f64 = 5.0;

fn label(
    text: String,
    position: msg::Point2,
    color: msg::Color,
    stamp: msg::Time,
) -> msg::TextAnnotation {
    msg::TextAnnotation {
        timestamp: stamp,
        position,
        text,
        font_size: 12.0,
        text_color: color,
        background_color: CLEAR,
    }
}

/// The measured centroids: one `POINTS` annotation (green dots), each labelled with its point id below and to the
/// left of it (the projected point's label goes to the right, so the two stay apart).
fn measured_annotations(
    measured: &[Measurement],
    stamp: msg::Time,
    annotations: &mut msg::ImageAnnotations,
) {
    if measured.is_empty() {
        return;
    }
    let points: Vec<msg::Point2> = measured
        .iter()
        .map(|m| msg::Point2 {
            x: m.u_px,
            y: m.v_px,
        })
        .collect();
    annotations.points.push(msg::PointsAnnotation {
        timestamp: stamp,
        r#type: 1, // POINTS
        points,
        outline_color: MEASURED_COLOR,
        outline_colors: Vec::new(),
        fill_color: MEASURED_COLOR,
        thickness: MEASURED_POINT_PX,
    });
    for m in measured {
        annotations.texts.push(label(
            m.id.to_string(),
            msg::Point2 {
                x: m.u_px - 14.0,
                y: m.v_px + 14.0,
            },
            MEASURED_COLOR,
            stamp,
        ));
    }
}

/// The target's points projected by `state` through the camera model (lens distortion included): magenta circles,
/// the size of the blob's disk where the target gives its diameter, each labelled with its point id to the right.
fn projected_annotations(
    camera: &CameraModel,
    target: &Target,
    state: &MotionState,
    stamp: msg::Time,
    annotations: &mut msg::ImageAnnotations,
) {
    let focal_px = camera.intrinsics.fx_px;
    for point in target.points() {
        let in_cam = state.cam_r_obj * point.point_in_obj_m + state.cam_t_obj_m;
        let Some(pixel) = camera.raw_pixel_from_cam(&in_cam) else {
            continue;
        };
        let position = msg::Point2 {
            x: pixel.x,
            y: pixel.y,
        };
        // The disk's apparent diameter, or a fixed mark where the target gives none.
        let diameter = point
            .diameter_m
            .map_or(8.0, |d| focal_px * d / in_cam.z.max(1e-6));
        annotations.circles.push(msg::CircleAnnotation {
            timestamp: stamp,
            position,
            diameter,
            thickness: 1.5,
            fill_color: CLEAR,
            outline_color: PROJECTED_COLOR,
        });
        annotations.texts.push(label(
            point.id.to_string(),
            msg::Point2 {
                x: pixel.x + 0.5 * diameter + 2.0,
                y: pixel.y,
            },
            PROJECTED_COLOR,
            stamp,
        ));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::BagFrameSource;
    use roitrack_core::camera::{Distortion, Equidistant, RationalPolynomial};

    #[test]
    fn the_camera_info_names_the_cameras_own_distortion_model() {
        let dir = tempfile::tempdir().unwrap();
        let canonical = CameraModel::canonical();
        for distortion in [
            canonical.distortion,
            Distortion::from(RationalPolynomial::from_coefficients([
                0.1, -0.2, 1e-3, -2e-3, 0.05, 0.3, -0.1, 0.02,
            ])),
            Distortion::from(Equidistant::from_coefficients([0.1, -0.02, 3e-3, -4e-4])),
        ] {
            let camera = CameraModel {
                distortion,
                ..canonical.clone()
            };
            let path = dir.path().join(format!("{}.mcap", distortion.model_name()));
            let mut bag =
                BagWriter::create(&path, &BagOptions::default(), Some(camera.clone())).unwrap();
            let mut frame = Frame::default();
            frame.resize(camera.width_px, camera.height_px, 8);
            bag.write_frame(&frame, None, &[]).unwrap();
            bag.finish().unwrap();
            let mut source = BagFrameSource::open(&path, topics::IMAGE).unwrap();
            let read = source.camera_info(topics::CAMERA_INFO).unwrap();
            assert_eq!(read.distortion, distortion, "{}", distortion.model_name());
            assert_eq!(read.intrinsics, camera.intrinsics);
        }
    }
}
