//! [`MeasurementSubscriber`] (feature `ros2`): blob centroids (`roitrack_msgs/msg/BlobMeasurements`, the message
//! the bags carry on `/roitrack/measurements`) taken live from the ROS 2 DDS bus, for `roitrack ros2-node`, and the
//! camera of a `sensor_msgs/msg/CameraInfo` topic ([`wait_for_camera_info`]).

use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use roitrack_core::{CameraModel, Measurement};
use roitrack_formats::{FrameInfo, MeasurementChecks};
use roitrack_image::Frame;
use ros2_client::dds::rustdds::{
    self, DomainParticipantBuilder, QosPolicies, RepresentationIdentifier, TopicKind, no_key,
};
use ros2_client::{
    MessageTypeName, Name, QosProfile,
    qos::{Durability, History},
};

use crate::input_counts::{InputCounts, LeftOut};
use crate::measurement_reader::decode;
use crate::msg::BLOB_MEASUREMENTS;
use crate::reader::{IMAGE_TYPES, ImageFault, camera_from_info, compressed_image, decode_image};
use crate::ros2::{Ros2Error, Ros2Options, check_interfaces, normalised_namespace};

/// The type of a camera info.
const CAMERA_INFO: &str = "sensor_msgs/msg/CameraInfo";
/// How often the subscriber looks for a message when none is waiting.
const POLL: Duration = Duration::from_micros(200);
/// The messages kept until taken: a tracker behind by this many messages loses the oldest (counted by DDS, not here).
const DEPTH: usize = 1000;
/// The messages left out whose reasons are kept (all are counted).
pub const REASONS_KEPT: usize = 16;

/// A message's serialised body as DDS delivered it, with its encoding.
#[derive(Debug, Clone)]
pub(crate) struct RawMessage {
    encoding: RepresentationIdentifier,
    bytes: Vec<u8>,
}

impl RawMessage {
    /// The message as a bag holds it: the encapsulation header DDS took off (the representation, then two bytes of
    /// options), then the body.
    fn with_header(&self) -> Vec<u8> {
        let mut bytes = Vec::with_capacity(4 + self.bytes.len());
        bytes.extend_from_slice(&self.encoding.to_bytes());
        bytes.extend_from_slice(&[0, 0]);
        bytes.extend_from_slice(&self.bytes);
        bytes
    }
}

/// Takes every message as its bytes: roitrack decodes them itself, so that a malformed one is named and counted,
/// never a failure of the subscription.
#[derive(Debug, Clone, Copy)]
pub(crate) struct RawAdapter;

impl no_key::DeserializerAdapter<RawMessage> for RawAdapter {
    type Error = std::convert::Infallible;
    type Decoded = RawMessage;

    fn supported_encodings() -> &'static [RepresentationIdentifier] {
        &[
            RepresentationIdentifier::CDR_LE,
            RepresentationIdentifier::CDR_BE,
            RepresentationIdentifier::PL_CDR_LE,
            RepresentationIdentifier::PL_CDR_BE,
            RepresentationIdentifier::CDR2_LE,
            RepresentationIdentifier::CDR2_BE,
            RepresentationIdentifier::D_CDR_LE,
            RepresentationIdentifier::D_CDR_BE,
        ]
    }

    fn transform_decoded(decoded: RawMessage) -> RawMessage {
        decoded
    }
}

impl no_key::DefaultDecoder<RawMessage> for RawAdapter {
    type Decoder = RawAdapter;
    const DECODER: RawAdapter = RawAdapter;
}

impl<'de> no_key::Decode<'de, RawMessage> for RawAdapter {
    type Error = std::convert::Infallible;

    fn decode_bytes(
        self,
        input_bytes: &'de [u8],
        encoding: RepresentationIdentifier,
    ) -> Result<RawMessage, Self::Error> {
        Ok(RawMessage {
            encoding,
            bytes: input_bytes.to_vec(),
        })
    }
}

/// What a subscriber received.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SubscriberReport {
    /// Messages taken.
    pub messages: u64,
    /// Centroids (of an [`ImageSubscriber`]: frames) handed on to the tracker.
    pub measurements: u64,
    /// Messages left out whole because something in them was wrong.
    pub malformed: u64,
    /// Why, for the first 16 of them: `message N: field F: what`.
    pub reasons: Vec<String>,
}

/// What a subscriber keeps of the messages it takes: its topic, its report, and the counts by reason it shares with
/// the status ([`InputCounts`]).
struct Intake {
    topic: String,
    report: SubscriberReport,
    counts: Arc<InputCounts>,
}

impl Intake {
    fn new(topic: String) -> Self {
        Self {
            topic,
            report: SubscriberReport::default(),
            counts: Arc::default(),
        }
    }

    /// Counts a message taken; its index on the topic.
    fn take(&mut self) -> u64 {
        let index = self.report.messages;
        self.report.messages += 1;
        self.counts.taken();
        index
    }

    /// Counts message `index` as left out for `why`, keeping the reason if there is room.
    fn left_out(&mut self, index: u64, why: LeftOut, reason: String) {
        self.report.malformed += 1;
        self.counts.left_out(why);
        if self.report.reasons.len() < REASONS_KEPT {
            self.report
                .reasons
                .push(format!("{} message {index}: {reason}", self.topic));
        }
    }
}

/// A participant of the domain and interfaces of `options` and a reader of `topic` (in the namespace of `options`;
/// the DDS topic `rt` and its name) of type `full_type` (`pkg/msg/Type`) that takes its messages as their bytes; and
/// the topic's name with its namespace.
fn subscribe(
    options: &Ros2Options,
    topic: &str,
    full_type: &str,
    qos: &QosProfile,
) -> Result<
    (
        String,
        rustdds::DomainParticipant,
        no_key::SimpleDataReader<RawMessage, RawAdapter>,
    ),
    Ros2Error,
> {
    check_interfaces(&options.interfaces)?;
    let full = format!("{}{topic}", normalised_namespace(&options.namespace));
    let name = Name::parse(&full).map_err(|e| Ros2Error::Namespace {
        namespace: full.clone(),
        message: e.to_string(),
    })?;
    let (participant, reader) = raw_reader(options, &name, full_type, qos)?;
    Ok((full, participant, reader))
}

/// A subscriber's reader and what it keeps of the messages it takes, with when it stops: when `stop` is raised, or
/// when no message has come for `idle` after the first one.
struct Subscription {
    reader: no_key::SimpleDataReader<RawMessage, RawAdapter>,
    // Kept alive with the reader.
    _participant: rustdds::DomainParticipant,
    intake: Intake,
    stop: Arc<AtomicBool>,
    idle: Duration,
    last_message: Option<Instant>,
}

impl Subscription {
    /// Subscribes to `topic` (in the namespace of `options`) of type `full_type` ([`subscribe`]).
    fn start(
        options: &Ros2Options,
        topic: &str,
        full_type: &str,
        qos: &QosProfile,
        stop: Arc<AtomicBool>,
        idle: Duration,
    ) -> Result<Self, Ros2Error> {
        let (full, participant, reader) = subscribe(options, topic, full_type, qos)?;
        Ok(Self {
            reader,
            _participant: participant,
            intake: Intake::new(full),
            stop,
            idle,
            last_message: None,
        })
    }

    /// The next message DDS hands over (not yet counted as taken); blocks until one comes, `None` when `stop` is
    /// raised or no message came for `idle`.
    fn next_message(&mut self) -> Option<RawMessage> {
        loop {
            if self.stop.load(Ordering::Relaxed) {
                return None;
            }
            match self.reader.try_take_one() {
                Ok(Some(change)) => {
                    self.last_message = Some(Instant::now());
                    return Some(change.into_value());
                }
                Err(e) => {
                    // A sample DDS could not hand over (an encoding no adapter takes, ...): counted and named too.
                    let index = self.intake.take();
                    self.intake
                        .left_out(index, LeftOut::Malformed, format!("not taken: {e}"));
                }
                Ok(None) => {
                    if self.last_message.is_some_and(|t| t.elapsed() >= self.idle) {
                        return None;
                    }
                    std::thread::sleep(POLL);
                }
            }
        }
    }
}

/// The centroids of a `roitrack_msgs/msg/BlobMeasurements` topic on the ROS 2 DDS bus, as an iterator of
/// [`Measurement`]s in the order they come (each at `header.stamp + dt_s`), blocking until the next one; it ends when
/// `stop` is raised, or when no message has come for `idle` after the first one.
///
/// Subscribed reliable (keep last 1,000): every centroid matters to the estimator, so a publisher of them must offer
/// reliable. Every message is checked whole before any of its centroids is handed on, as a measurements file's rows
/// are (arrays of one entry per centroid, finite values, the target's point ids, centroids on the image, times that
/// never go back): one that fails, or that is not little-endian CDR, is left out whole, counted, and its reason kept
/// ([`report`](Self::report)); the subscription goes on.
///
/// ```no_run
/// use std::sync::{Arc, atomic::AtomicBool};
/// use std::time::Duration;
/// use roitrack_formats::MeasurementChecks;
/// use roitrack_ros::ros2::Ros2Options;
/// use roitrack_ros::ros2_input::MeasurementSubscriber;
///
/// let checks = MeasurementChecks::new().with_known_ids(0..16).with_image_size(1024, 1024);
/// let stop = Arc::new(AtomicBool::new(false));
/// let mut centroids = MeasurementSubscriber::start(
///     &Ros2Options::default(), "/roitrack/measurements", checks, stop, Duration::from_secs(3),
/// )
/// .unwrap();
/// for m in &mut centroids {
///     let m = m.unwrap();
///     println!("point {} at {} s: ({}, {}) px", m.id, m.t_s, m.u_px, m.v_px);
/// }
/// println!("{} malformed messages: {:?}", centroids.report().malformed, centroids.report().reasons);
/// ```
pub struct MeasurementSubscriber {
    subscription: Subscription,
    checks: MeasurementChecks,
    pending: VecDeque<Measurement>,
    decoded: VecDeque<Measurement>,
}

impl std::fmt::Debug for MeasurementSubscriber {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MeasurementSubscriber")
            .field("topic", &self.subscription.intake.topic)
            .field("report", &self.subscription.intake.report)
            .finish_non_exhaustive()
    }
}

impl MeasurementSubscriber {
    /// Subscribes to `topic` (in the namespace of `options`) on the domain and interfaces of `options`; `checks`
    /// are the checks of every centroid (the target's ids, the image's size).
    pub fn start(
        options: &Ros2Options,
        topic: &str,
        checks: MeasurementChecks,
        stop: Arc<AtomicBool>,
        idle: Duration,
    ) -> Result<Self, Ros2Error> {
        let qos = QosProfile::subscription_default()
            .reliability_reliable(ros2_client::qos::WhenFull::Fail)
            .history(History::KeepLast { depth: DEPTH });
        Ok(Self {
            subscription: Subscription::start(options, topic, BLOB_MEASUREMENTS, &qos, stop, idle)?,
            checks,
            pending: Default::default(),
            decoded: Default::default(),
        })
    }

    /// The topic subscribed to (with its namespace).
    pub fn topic(&self) -> &str {
        &self.subscription.intake.topic
    }

    /// What was received so far.
    pub fn report(&self) -> &SubscriberReport {
        &self.subscription.intake.report
    }

    /// The messages taken and those left out by reason, as they are counted (for the status:
    /// [`Ros2Publisher::start_counting_inputs`](crate::ros2::Ros2Publisher::start_counting_inputs)).
    pub fn counts(&self) -> Arc<InputCounts> {
        Arc::clone(&self.subscription.intake.counts)
    }

    /// Decodes and checks one message whole; its centroids to `pending`, or the reason it is left out.
    fn take_message(&mut self, message: RawMessage) {
        let index = self.subscription.intake.take();
        match checked_message(&self.checks, &message, &mut self.decoded) {
            Ok(checks) => {
                self.checks = checks;
                self.subscription.intake.report.measurements += self.decoded.len() as u64;
                self.pending.extend(self.decoded.drain(..));
            }
            Err((why, reason)) => self.subscription.intake.left_out(index, why, reason),
        }
    }
}

/// Decodes `message` into `out` and checks it whole against `checks` (on a copy: a message that fails changes
/// nothing of what later ones are checked against); the checks as they stand after it, or why it is left out: a
/// message that does not decode is malformed, one whose centroids fail the checks invalid.
fn checked_message(
    checks: &MeasurementChecks,
    message: &RawMessage,
    out: &mut VecDeque<Measurement>,
) -> Result<MeasurementChecks, (LeftOut, String)> {
    out.clear();
    decode(&message.with_header(), out)
        .map_err(|(field, e)| (LeftOut::Malformed, format!("field {field}: {e}")))?;
    let mut checks = checks.clone();
    for (k, m) in out.iter().enumerate() {
        checks
            .check(m)
            .map_err(|problem| (LeftOut::Invalid, format!("centroid {k}: {problem}")))?;
    }
    Ok(checks)
}

/// A participant of the domain and interfaces of `options` and a reader of the topic `name` (a ROS 2 name: the DDS
/// topic `rt` and the name) of type `full_type` (`pkg/msg/Type`) that takes its messages as their bytes.
fn raw_reader(
    options: &Ros2Options,
    name: &Name,
    full_type: &str,
    qos: &QosProfile,
) -> Result<
    (
        rustdds::DomainParticipant,
        no_key::SimpleDataReader<RawMessage, RawAdapter>,
    ),
    Ros2Error,
> {
    let start_error = |message: String| Ros2Error::Start {
        domain_id: options.domain_id,
        message,
    };
    let mut builder = DomainParticipantBuilder::new(options.domain_id);
    if !options.interfaces.is_empty() {
        builder = builder.with_only_networks(options.interfaces.iter().copied());
    }
    let participant = builder.build().map_err(|e| start_error(e.to_string()))?;
    let qos: QosPolicies = qos.into();
    let (package, type_name) = full_type.split_once("/msg/").expect("a pkg/msg/Type name");
    let dds_topic = participant
        .create_topic(
            format!("rt{name}"),
            MessageTypeName::new(package, type_name).dds_msg_type(),
            &qos,
            TopicKind::NoKey,
        )
        .map_err(|e| start_error(format!("cannot create the topic {name}: {e}")))?;
    let reader = participant
        .create_subscriber(&qos)
        .and_then(|s| s.create_simple_datareader_no_key(&dds_topic, Some(qos.clone())))
        .map_err(|e| start_error(format!("cannot subscribe to {name}: {e}")))?;
    Ok((participant, reader))
}

/// The camera of the first well-formed `sensor_msgs/msg/CameraInfo` on `topic` (in the namespace of `options`),
/// waiting up to `timeout` (or until `stop`). Subscribed twice, so that every publisher is matched: best effort and
/// volatile (a camera driver's camera info beside each image), reliable and transient local (a latched one, sent
/// once, as `--ros2` publishes it). A malformed camera info is named and waited past; none in time is an error that
/// names the topic, the wait and what was wrong with those that came.
///
/// ```no_run
/// use std::sync::atomic::AtomicBool;
/// use std::time::Duration;
/// use roitrack_ros::ros2::Ros2Options;
///
/// let stop = AtomicBool::new(false);
/// let camera = roitrack_ros::ros2_input::wait_for_camera_info(
///     &Ros2Options::default(), "/camera/camera_info", Duration::from_secs(10), &stop,
/// )
/// .unwrap();
/// println!("{} x {} px, fx {} px", camera.width_px, camera.height_px, camera.intrinsics.fx_px);
/// ```
pub fn wait_for_camera_info(
    options: &Ros2Options,
    topic: &str,
    timeout: Duration,
    stop: &AtomicBool,
) -> Result<CameraModel, Ros2Error> {
    wait_for_camera_info_with(options, topic, timeout, stop, || {})
}

/// [`wait_for_camera_info`], calling `while_waiting` at each look at the bus (an [`ImageSubscriber`] counts the
/// images that come before the camera info there: [`ImageSubscriber::discard_waiting`]).
pub fn wait_for_camera_info_with(
    options: &Ros2Options,
    topic: &str,
    timeout: Duration,
    stop: &AtomicBool,
    mut while_waiting: impl FnMut(),
) -> Result<CameraModel, Ros2Error> {
    let volatile = QosProfile::subscription_default();
    let latched = QosProfile::subscription_default()
        .reliability_reliable(ros2_client::qos::WhenFull::Fail)
        .durability(Durability::TransientLocal);
    let readers = [
        subscribe(options, topic, CAMERA_INFO, &volatile)?,
        subscribe(options, topic, CAMERA_INFO, &latched)?,
    ];
    let full = readers[0].0.clone();
    let start = Instant::now();
    let mut malformed = Vec::new();
    while start.elapsed() < timeout && !stop.load(Ordering::Relaxed) {
        for (_, _, reader) in &readers {
            while let Ok(Some(change)) = reader.try_take_one() {
                match camera_from_info(&change.into_value().with_header()) {
                    Ok(camera) => return Ok(camera),
                    Err(e) => malformed.push(e),
                }
            }
        }
        while_waiting();
        std::thread::sleep(POLL);
    }
    Err(Ros2Error::Input(format!(
        "no camera info on {full} within {:.1} s{}",
        timeout.as_secs_f64(),
        match malformed.len() {
            0 => ": give --camera, or publish the camera's sensor_msgs/msg/CameraInfo there"
                .to_string(),
            n => format!(", {n} malformed (the first: {})", malformed[0]),
        }
    )))
}

impl Iterator for MeasurementSubscriber {
    type Item = Result<Measurement, std::convert::Infallible>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(m) = self.pending.pop_front() {
                return Some(Ok(m));
            }
            let message = self.subscription.next_message()?;
            self.take_message(message);
        }
    }
}

/// The images of a `sensor_msgs/msg/Image` (or `sensor_msgs/msg/CompressedImage`) topic on the ROS 2 DDS bus, one
/// frame at a time ([`next_frame`](Self::next_frame)), each at its header stamp, for the frame tracker
/// (`roitrack ros2-node --image-topic`).
///
/// Encodings `mono8`, `mono16` (either byte order) and `bgr8`, `rgb8` (made grey by BT.601 luma, as image files are);
/// a compressed image in any format `track --images` reads (PNG, JPEG, ...). An image that cannot be tracked is left
/// out, counted and its reason kept ([`report`](Self::report)), and the subscription goes on: another encoding, a
/// step or data size that does not match its width and height, a size other than the camera's, a time not after the
/// previous image's, or an image that came before any camera info ([`discard_waiting`](Self::discard_waiting)).
/// Subscribed reliable (keep last 100) by default, as `image_transport` publishes, or best effort (a camera driver's
/// sensor-data QoS).
pub struct ImageSubscriber {
    subscription: Subscription,
    compressed: bool,
    expected_size: Option<(u32, u32)>,
    last_t_s: Option<f64>,
}

impl std::fmt::Debug for ImageSubscriber {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ImageSubscriber")
            .field("topic", &self.subscription.intake.topic)
            .field("report", &self.subscription.intake.report)
            .finish_non_exhaustive()
    }
}

/// The images kept until taken.
const IMAGE_DEPTH: usize = 100;

impl ImageSubscriber {
    /// Subscribes to `topic` (in the namespace of `options`), of type `sensor_msgs/msg/CompressedImage` if
    /// `compressed`, else `sensor_msgs/msg/Image`; reliable, or best effort if `best_effort`. Ends when `stop` is
    /// raised or no image has come for `idle` after the first one.
    pub fn start(
        options: &Ros2Options,
        topic: &str,
        compressed: bool,
        best_effort: bool,
        stop: Arc<AtomicBool>,
        idle: Duration,
    ) -> Result<Self, Ros2Error> {
        let qos =
            QosProfile::subscription_default().history(History::KeepLast { depth: IMAGE_DEPTH });
        let qos = if best_effort {
            qos.reliability_best_effort()
        } else {
            qos.reliability_reliable(ros2_client::qos::WhenFull::Fail)
        };
        let type_name = if compressed {
            IMAGE_TYPES[1]
        } else {
            IMAGE_TYPES[0]
        };
        Ok(Self {
            subscription: Subscription::start(options, topic, type_name, &qos, stop, idle)?,
            compressed,
            expected_size: None,
            last_t_s: None,
        })
    }

    /// The topic subscribed to (with its namespace).
    pub fn topic(&self) -> &str {
        &self.subscription.intake.topic
    }

    /// What was received so far: `measurements` counts the frames handed on.
    pub fn report(&self) -> &SubscriberReport {
        &self.subscription.intake.report
    }

    /// The images taken and those left out by reason, as they are counted (for the status:
    /// [`Ros2Publisher::start_counting_inputs`](crate::ros2::Ros2Publisher::start_counting_inputs); the frame
    /// tracker's refusals are counted there too, as [`LeftOut::TooClose`]).
    pub fn counts(&self) -> Arc<InputCounts> {
        Arc::clone(&self.subscription.intake.counts)
    }

    /// From now on, every image must be `width` x `height` px (the camera's).
    pub fn expect_size(&mut self, width: u32, height: u32) {
        self.expected_size = Some((width, height));
    }

    /// Takes every image waiting and leaves it out, counted and named: called while there is no camera yet.
    pub fn discard_waiting(&mut self) {
        while let Ok(Some(change)) = self.subscription.reader.try_take_one() {
            drop(change);
            // Not a message of the tracking: --idle-s counts from the first image tracked.
            let index = self.subscription.intake.take();
            self.subscription.intake.left_out(
                index,
                LeftOut::NoCameraInfo,
                "an image before any camera info".to_string(),
            );
        }
    }

    /// The next image that can be tracked, decoded into `frame` (its buffer reused, `t_s` its header stamp), and
    /// which it is; blocks until one comes, `None` when `stop` is raised or no image came for `idle`.
    pub fn next_frame(&mut self, frame: &mut Frame) -> Option<FrameInfo> {
        loop {
            let message = self.subscription.next_message()?;
            let index = self.subscription.intake.take();
            match self.decode(&message, frame) {
                Ok(t_s) => {
                    self.last_t_s = Some(t_s);
                    self.subscription.intake.report.measurements += 1;
                    frame.t_s = t_s;
                    return Some(FrameInfo {
                        index: index as usize,
                        name: format!("message {index} of {}", self.subscription.intake.topic),
                        t_s,
                    });
                }
                Err((why, reason)) => self.subscription.intake.left_out(index, why, reason),
            }
        }
    }

    /// Decodes one image into `frame` and checks it; its stamp (s), or why it is left out.
    fn decode(&self, message: &RawMessage, frame: &mut Frame) -> Result<f64, (LeftOut, String)> {
        checked_image(
            message,
            self.compressed
                .then_some(self.subscription.intake.topic.as_str()),
            self.expected_size,
            self.last_t_s,
            frame,
        )
    }
}

/// Decodes `message` (a `sensor_msgs/msg/Image`, or a `CompressedImage` of the topic `compressed`) into `frame` and
/// checks it against the camera's size (`None`: no camera yet) and the previous image's stamp; its stamp (s), or why
/// it is left out (a compressed image that does not decode is [`LeftOut::Malformed`]).
fn checked_image(
    message: &RawMessage,
    compressed: Option<&str>,
    expected_size: Option<(u32, u32)>,
    last_t_s: Option<f64>,
    frame: &mut Frame,
) -> Result<f64, (LeftOut, String)> {
    let bytes = message.with_header();
    let t_s = match compressed {
        Some(topic) => {
            let (t_s, format, data) =
                compressed_image(&bytes).map_err(|e| (LeftOut::Malformed, e))?;
            let name = std::path::PathBuf::from(format!("{topic} ({format})"));
            *frame = roitrack_formats::decode_frame(data, &name)
                .map_err(|e| (LeftOut::Malformed, e.to_string()))?;
            t_s
        }
        None => decode_image(&bytes, frame).map_err(|e| match e {
            ImageFault::Encoding(m) => (LeftOut::Encoding, m),
            ImageFault::Malformed(m) => (LeftOut::Malformed, m),
        })?,
    };
    let Some((width, height)) = expected_size else {
        return Err((
            LeftOut::NoCameraInfo,
            "an image before any camera info".to_string(),
        ));
    };
    if (frame.width, frame.height) != (width, height) {
        return Err((
            LeftOut::Size,
            format!(
                "the image is {} x {} px, the camera info says {width} x {height} px",
                frame.width, frame.height
            ),
        ));
    }
    if !t_s.is_finite() {
        return Err((
            LeftOut::StampOrder,
            format!("the stamp {t_s} s is not finite"),
        ));
    }
    if let Some(last) = last_t_s
        && t_s <= last
    {
        return Err((
            LeftOut::StampOrder,
            format!("the stamp {t_s} s does not come after the previous image's ({last} s)"),
        ));
    }
    Ok(t_s)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg;

    /// A message of two centroids (points 1 and 2) at 1.5 s, as DDS hands it over: its body and encoding.
    fn message(u_px: &[f64]) -> RawMessage {
        let header = msg::Header {
            stamp: msg::Time {
                sec: 1,
                nanosec: 500_000_000,
            },
            frame_id: "camera",
        };
        let bytes = cdr::serialize::<_, _, cdr::CdrLe>(
            &msg::BlobMeasurements {
                header,
                point_ids: msg::Seq(&[1, 2]),
                u_px: msg::Seq(u_px),
                v_px: msg::Seq(&[20.0, 30.0]),
                dt_s: msg::Seq(&[0.0, 0.25e-3]),
                sigma_px: msg::Seq(&[]),
            },
            cdr::Infinite,
        )
        .unwrap();
        RawMessage {
            encoding: RepresentationIdentifier::CDR_LE,
            bytes: bytes[4..].to_vec(),
        }
    }

    #[test]
    fn a_message_is_checked_whole_and_a_bad_one_named_and_left_out() {
        let checks = MeasurementChecks::new()
            .with_known_ids([1, 2])
            .with_image_size(640, 480);
        let mut out = VecDeque::new();
        let after = checked_message(&checks, &message(&[10.0, 11.0]), &mut out).unwrap();
        assert_eq!(out.len(), 2);
        assert_eq!((out[1].id, out[1].t_s, out[1].u_px), (2, 1.50025, 11.0));
        // The same message again goes back in time (a point measured twice at a time), on the checks after it.
        let (why, again) = checked_message(&after, &message(&[10.0, 11.0]), &mut out).unwrap_err();
        assert!(again.starts_with("centroid 0:"), "{again}");
        assert_eq!(why, LeftOut::Invalid);
        for (message, expected, expected_why) in [
            (
                message(&[10.0]),
                "field u_px: 1 entries for 2 point ids",
                LeftOut::Malformed,
            ),
            (
                message(&[10.0, f64::NAN]),
                "field u_px[1]: NaN is not finite",
                LeftOut::Malformed,
            ),
            (message(&[10.0, 900.0]), "centroid 1:", LeftOut::Invalid),
            (
                RawMessage {
                    encoding: RepresentationIdentifier::CDR_BE,
                    ..message(&[10.0, 11.0])
                },
                "big-endian CDR is not supported",
                LeftOut::Malformed,
            ),
            (
                RawMessage {
                    encoding: RepresentationIdentifier::CDR_LE,
                    bytes: vec![0; 6],
                },
                "field header",
                LeftOut::Malformed,
            ),
        ] {
            let (why, reason) = checked_message(&checks, &message, &mut out).unwrap_err();
            assert!(reason.contains(expected), "{reason}, not {expected}");
            assert_eq!(why, expected_why, "{reason}");
        }
    }

    /// A `sensor_msgs/msg/Image` at 2.25 s, as DDS hands it over.
    fn image(encoding: &str, width: u32, height: u32, step: u32, data: &[u8]) -> RawMessage {
        let bytes = cdr::serialize::<_, _, cdr::CdrLe>(
            &msg::Image {
                header: msg::Header {
                    stamp: msg::Time {
                        sec: 2,
                        nanosec: 250_000_000,
                    },
                    frame_id: "camera",
                },
                height,
                width,
                encoding,
                is_bigendian: 0,
                step,
                data: msg::Bytes(data),
            },
            cdr::Infinite,
        )
        .unwrap();
        RawMessage {
            encoding: RepresentationIdentifier::CDR_LE,
            bytes: bytes[4..].to_vec(),
        }
    }

    #[test]
    fn an_image_is_decoded_checked_and_a_bad_one_named() {
        let mut frame = Frame::default();
        let pixels: Vec<u8> = (0..12).collect();
        let good = image("mono8", 4, 3, 4, &pixels);
        let t_s = checked_image(&good, None, Some((4, 3)), Some(2.0), &mut frame).unwrap();
        assert_eq!(
            (t_s, frame.width, frame.height, frame.pixels[5]),
            (2.25, 4, 3, 5)
        );
        let bad = [
            (
                good.clone(),
                None,
                None,
                "an image before any camera info",
                LeftOut::NoCameraInfo,
            ),
            (
                good.clone(),
                Some((5, 3)),
                None,
                "the image is 4 x 3 px, the camera info says 5 x 3 px",
                LeftOut::Size,
            ),
            (
                good.clone(),
                Some((4, 3)),
                Some(2.25),
                "does not come after the previous image's",
                LeftOut::StampOrder,
            ),
            (
                image("yuv422", 4, 3, 8, &pixels),
                Some((4, 3)),
                None,
                "image encoding \"yuv422\" is not read",
                LeftOut::Encoding,
            ),
            (
                image("mono8", 4, 3, 3, &pixels),
                Some((4, 3)),
                None,
                "with a step of 3",
                LeftOut::Malformed,
            ),
            (
                image("mono8", 4, 3, 4, &pixels[..8]),
                Some((4, 3)),
                None,
                "8 bytes of data",
                LeftOut::Malformed,
            ),
        ];
        for (message, size, last, expected, expected_why) in bad {
            let (why, reason) = checked_image(&message, None, size, last, &mut frame).unwrap_err();
            assert!(reason.contains(expected), "{reason}, not {expected}");
            assert_eq!(why, expected_why, "{reason}");
        }
    }

    /// A `sensor_msgs/msg/CompressedImage`: a PNG of a frame, read as `track --images` reads files.
    #[test]
    fn a_compressed_image_is_decoded_and_a_bad_one_named() {
        #[derive(serde::Serialize)]
        struct CompressedImage<'a> {
            header: msg::Header<'a>,
            format: &'a str,
            data: msg::Bytes<'a>,
        }
        let raw = |data: &[u8]| {
            let bytes = cdr::serialize::<_, _, cdr::CdrLe>(
                &CompressedImage {
                    header: msg::Header {
                        stamp: msg::Time { sec: 3, nanosec: 0 },
                        frame_id: "camera",
                    },
                    format: "png",
                    data: msg::Bytes(data),
                },
                cdr::Infinite,
            )
            .unwrap();
            RawMessage {
                encoding: RepresentationIdentifier::CDR_LE,
                bytes: bytes[4..].to_vec(),
            }
        };
        let mut frame = Frame::default();
        frame.resize(5, 4, 8);
        frame
            .pixels
            .iter_mut()
            .enumerate()
            .for_each(|(k, v)| *v = k as u16);
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("f.png");
        roitrack_formats::write_frame_png(&path, &frame).unwrap();
        let png = std::fs::read(&path).unwrap();
        let mut decoded = Frame::default();
        let t_s = checked_image(&raw(&png), Some("/c"), Some((5, 4)), None, &mut decoded).unwrap();
        assert_eq!((t_s, decoded.width, decoded.height), (3.0, 5, 4));
        assert_eq!(decoded.pixels, frame.pixels);
        let (why, reason) = checked_image(
            &raw(&png[..20]),
            Some("/c"),
            Some((5, 4)),
            None,
            &mut decoded,
        )
        .unwrap_err();
        assert!(reason.contains("/c (png)"), "{reason}");
        assert_eq!(why, LeftOut::Malformed);
    }
}
